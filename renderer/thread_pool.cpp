#include "renderer/thread_pool.h"

#include <algorithm>
#include <atomic>
#include <exception>

#include <pmmintrin.h>
#include <xmmintrin.h>

namespace tessera {

namespace {

// Hardware threads, at least one (the standard allows 0 for "unknown").
unsigned hardware_threads() {
  return std::max(1u, std::thread::hardware_concurrency());
}

}  // namespace

void enable_flush_to_zero() {
  _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
  _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
}

struct ThreadPool::Batch {
  const std::function<void(size_t, int)>* fn;
  size_t count;
  size_t next = 0;      // next item to hand out (guarded by the pool mutex)
  size_t finished = 0;  // items done (guarded by the pool mutex)
  std::exception_ptr error;
  std::condition_variable done_cv;
};

ThreadPool::ThreadPool(int threads) {
  int n = threads > 0 ? threads : static_cast<int>(hardware_threads());
  workers_.reserve(n);
  for (int i = 0; i < n; ++i) workers_.emplace_back([this, i] { worker_main(i); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  work_cv_.notify_all();
  for (std::thread& t : workers_) t.join();
}

int ThreadPool::busy() const {
  std::lock_guard lock(mutex_);
  return busy_;
}

void ThreadPool::parallel_for(size_t count, const std::function<void(size_t, int)>& fn) {
  if (count == 0) return;
  Batch batch;
  batch.fn = &fn;
  batch.count = count;
  std::unique_lock lock(mutex_);
  active_.push_back(&batch);
  work_cv_.notify_all();
  batch.done_cv.wait(lock, [&] { return batch.finished == batch.count; });
  lock.unlock();
  if (batch.error) std::rethrow_exception(batch.error);
}

void ThreadPool::worker_main(int index) {
  enable_flush_to_zero();
  std::unique_lock lock(mutex_);
  for (;;) {
    work_cv_.wait(lock, [&] { return stopping_ || !active_.empty(); });
    if (stopping_ && active_.empty()) return;
    // Take one item from the next batch in turn.
    round_robin_ = round_robin_ % active_.size();
    Batch* batch = active_[round_robin_];
    size_t item = batch->next++;
    if (batch->next >= batch->count) {
      active_.erase(active_.begin() + static_cast<std::ptrdiff_t>(round_robin_));
    } else {
      ++round_robin_;
    }
    ++busy_;
    const bool skip = batch->error != nullptr;  // a failed batch drains without running more items
    lock.unlock();
    std::exception_ptr error;
    if (!skip) {
      try {
        (*batch->fn)(item, index);
      } catch (...) {
        error = std::current_exception();
      }
    }
    lock.lock();
    --busy_;
    if (error && !batch->error) batch->error = error;
    if (++batch->finished == batch->count) batch->done_cv.notify_all();
  }
}

namespace {

// The helper-thread budget of run_in_parallel.
std::mutex g_helpers_mutex;
int g_helpers_limit = -1;  // unset: one per hardware thread but one
int g_helpers_used = 0;

int take_helpers(int wanted) {
  std::lock_guard lock(g_helpers_mutex);
  const int limit = g_helpers_limit >= 0 ? g_helpers_limit : static_cast<int>(hardware_threads()) - 1;
  const int taken = std::clamp(limit - g_helpers_used, 0, std::max(wanted, 0));
  g_helpers_used += taken;
  return taken;
}

void give_back_helpers(int count) {
  std::lock_guard lock(g_helpers_mutex);
  g_helpers_used -= count;
}

}  // namespace

void limit_parallel_helpers(int helpers) {
  std::lock_guard lock(g_helpers_mutex);
  g_helpers_limit = std::max(helpers, 0);
}

void run_in_parallel(size_t count, const std::function<void(size_t)>& fn, unsigned max_threads) {
  if (count == 0) return;
  const unsigned hardware = hardware_threads();
  const size_t wanted = std::min<size_t>(count, max_threads ? std::min(max_threads, hardware) : hardware);
  const int helper_budget = count > 1 ? take_helpers(static_cast<int>(wanted) - 1) : 0;
  struct GiveBack {
    int count;
    ~GiveBack() { give_back_helpers(count); }
  } give_back{helper_budget};
  const size_t threads = 1 + static_cast<size_t>(helper_budget);
  std::atomic<size_t> next{0};
  std::mutex error_mutex;
  std::exception_ptr error;  // of the lowest item that threw: the one a loop over the items would have stopped at
  size_t error_item = count;
  auto work = [&] {
    for (size_t i; (i = next.fetch_add(1)) < count;) {
      try {
        fn(i);
      } catch (...) {
        std::lock_guard lock(error_mutex);
        if (i < error_item) {
          error = std::current_exception();
          error_item = i;
        }
      }
    }
  };
  std::vector<std::thread> helpers;
  helpers.reserve(threads - 1);
  for (size_t t = 1; t < threads; ++t) {
    try {
      helpers.emplace_back(work);
    } catch (...) {
      break;  // out of threads or memory: the ones started (and this one) take the remaining items
    }
  }
  work();
  for (std::thread& t : helpers) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace tessera
