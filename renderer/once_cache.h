// A cache of shared values made once per key by concurrent callers (a "single flight"): the first caller for a key
// makes the value without holding the cache's lock, so callers for other keys are served meanwhile; callers for the
// same key wait for it and get its value, or its exception. Values are held weakly: an entry lives while someone
// holds its value, and entries nobody holds are dropped as new ones come. Used for decoded texture images, which
// several materials, and several jobs loading at once, may ask for.
#pragma once

#include <atomic>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <string>

namespace tessera {

template <typename Value>
class OnceCache {
 public:
  using Ptr = std::shared_ptr<const Value>;

  // The live value for `key`, or the one make() returns. An exception from make() reaches every caller waiting for
  // that key, and nothing is kept: the next caller tries again.
  Ptr get(const std::string& key, const std::function<Ptr()>& make) {
    std::unique_lock lock(mutex_);
    if (auto it = values_.find(key); it != values_.end())
      if (Ptr value = it->second.lock()) return value;
    if (auto it = pending_.find(key); it != pending_.end()) {
      std::shared_future<Ptr> pending = it->second;
      ++waiting_;
      lock.unlock();
      struct Done {
        std::atomic<int>& waiting;
        ~Done() { --waiting; }
      } done{waiting_};
      return pending.get();
    }
    std::promise<Ptr> promise;
    pending_.emplace(key, promise.get_future().share());
    lock.unlock();
    Ptr value;
    try {
      value = make();
    } catch (...) {
      lock.lock();
      pending_.erase(key);
      promise.set_exception(std::current_exception());
      throw;
    }
    lock.lock();
    std::erase_if(values_, [](const auto& entry) { return entry.second.expired(); });
    values_[key] = value;
    pending_.erase(key);
    promise.set_value(value);
    return value;
  }

  // Callers waiting, right now, for a value another caller is making (read without the lock).
  int waiting() const { return waiting_.load(); }

 private:
  mutable std::mutex mutex_;
  std::map<std::string, std::weak_ptr<const Value>> values_;
  std::map<std::string, std::shared_future<Ptr>> pending_;
  std::atomic<int> waiting_{0};
};

}  // namespace tessera
