// The single-flight cache behind texture loading: one make() per key however many callers ask at once, other keys
// served while a value is being made, errors shared with the waiters and not kept, values kept only while held.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <future>
#include <thread>

#include "renderer/once_cache.h"

namespace tessera {
namespace {

using Cache = OnceCache<int>;

// Polls `done` for up to 10 s (a guard against a deadlock, not a speed goal).
bool eventually(const std::function<bool()>& done) {
  for (int i = 0; i < 10000; ++i) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return done();
}

// A make() that signals it has started, then waits for the test to open its gate.
struct GatedMake {
  std::atomic<int> calls{0};
  std::atomic<bool> started{false};
  std::promise<void> gate;
  std::shared_future<void> opened = gate.get_future().share();
  int value;
  explicit GatedMake(int v) : value(v) {}
  std::function<Cache::Ptr()> fn() {
    return [this] {
      ++calls;
      started = true;
      opened.wait();
      return std::make_shared<const int>(value);
    };
  }
};

TEST(OnceCache, CallersOfOneKeyWaitForOneMake) {
  Cache cache;
  GatedMake make(7);
  auto first = std::async(std::launch::async, [&] { return cache.get("a", make.fn()); });
  ASSERT_TRUE(eventually([&] { return make.started.load(); }));
  auto second = std::async(std::launch::async, [&] { return cache.get("a", make.fn()); });
  EXPECT_TRUE(eventually([&] { return cache.waiting() == 1; }));  // the second caller waits, it does not make
  make.gate.set_value();
  Cache::Ptr a = first.get(), b = second.get();
  EXPECT_EQ(make.calls.load(), 1);
  EXPECT_EQ(a, b);
  EXPECT_EQ(*a, 7);
  EXPECT_EQ(cache.waiting(), 0);
}

TEST(OnceCache, OtherKeysAreServedWhileAValueIsMade) {
  Cache cache;
  GatedMake slow(1);
  auto blocked = std::async(std::launch::async, [&] { return cache.get("slow", slow.fn()); });
  ASSERT_TRUE(eventually([&] { return slow.started.load(); }));
  auto other =
      std::async(std::launch::async, [&] { return cache.get("fast", [] { return std::make_shared<const int>(2); }); });
  const bool served = other.wait_for(std::chrono::seconds(10)) == std::future_status::ready;
  slow.gate.set_value();  // let the slow one finish either way, so that a failure does not hang the test
  EXPECT_TRUE(served) << "a caller of another key waited for the value being made";
  EXPECT_EQ(*other.get(), 2);
  EXPECT_EQ(*blocked.get(), 1);
}

TEST(OnceCache, AnErrorReachesTheWaitersAndIsNotKept) {
  Cache cache;
  std::atomic<bool> started{false};
  std::promise<void> gate;
  std::shared_future<void> opened = gate.get_future().share();
  auto failing = [&]() -> Cache::Ptr {
    started = true;
    opened.wait();
    throw std::runtime_error("cannot decode");
  };
  auto first = std::async(std::launch::async, [&] { return cache.get("k", failing); });
  ASSERT_TRUE(eventually([&] { return started.load(); }));
  auto second = std::async(std::launch::async, [&] { return cache.get("k", failing); });
  EXPECT_TRUE(eventually([&] { return cache.waiting() == 1; }));
  gate.set_value();
  EXPECT_THROW(first.get(), std::runtime_error);
  EXPECT_THROW(second.get(), std::runtime_error);
  int calls = 0;
  Cache::Ptr again = cache.get("k", [&] {
    ++calls;
    return std::make_shared<const int>(3);
  });
  EXPECT_EQ(calls, 1);  // tried again, not answered with the old error
  EXPECT_EQ(*again, 3);
}

TEST(OnceCache, ValuesAreKeptOnlyWhileHeld) {
  Cache cache;
  int calls = 0;
  auto make = [&] {
    ++calls;
    return std::make_shared<const int>(calls);
  };
  Cache::Ptr held = cache.get("k", make);
  EXPECT_EQ(cache.get("k", make), held);
  EXPECT_EQ(calls, 1);
  held.reset();
  EXPECT_EQ(*cache.get("k", make), 2);  // nobody held it: made again
  EXPECT_EQ(calls, 2);
}

}  // namespace
}  // namespace tessera
