// A fixed pool of render threads shared by every render session of the process. Work arrives as batches of
// independent items (the tiles of a pass); idle threads take items from the active batches in turn, so concurrent
// sessions share the threads fairly.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace tessera {

class ThreadPool {
 public:
  // `threads` <= 0 uses every hardware thread.
  explicit ThreadPool(int threads = 0);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const { return static_cast<int>(workers_.size()); }
  // Number of threads running an item right now.
  int busy() const;

  // Runs fn(item, worker) for every item in [0, count) and returns when all have finished. `worker` is in
  // [0, size()) and no two items run on the same worker at once, so it can index per-thread scratch state.
  // The first exception thrown by an item is rethrown here after the batch has drained.
  void parallel_for(size_t count, const std::function<void(size_t item, int worker)>& fn);

 private:
  struct Batch;
  void worker_main(int index);

  mutable std::mutex mutex_;
  std::condition_variable work_cv_;
  std::vector<Batch*> active_;
  size_t round_robin_ = 0;
  int busy_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

// Runs fn(i) for every i in [0, count) on up to `max_threads` threads (0: one per hardware thread) started for the
// call, the calling thread among them, and returns when all items are done: for work outside a render, such as
// decoding a scene's images, where no pool is at hand. Runs on fewer threads when the system refuses to start one.
// The exception of the lowest item that threw (the one a loop over the items would report, whatever the timing) is
// rethrown here after the others have finished; a single item runs on the calling thread.
// Helper threads are a process-wide budget (limit_parallel_helpers): concurrent calls (jobs loading side by side,
// submissions checked on HTTP threads) share it, and a call that finds none free runs on the calling thread alone.
void run_in_parallel(size_t count, const std::function<void(size_t)>& fn, unsigned max_threads = 0);
// At most `helpers` threads, across the process, help run_in_parallel calls at once (default: one per hardware
// thread but one); a daemon sets it from its --threads.
void limit_parallel_helpers(int helpers);
// Sets flush-to-zero and denormals-are-zero on the calling thread, as Embree asks of every thread that traces rays
// (Embree 3 API reference, "Performance Recommendations"); the pool's threads set it when they start.
void enable_flush_to_zero();

}  // namespace tessera
