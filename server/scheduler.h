// Runs jobs: claims queued jobs from the store up to `max_jobs` at once and renders each on its own thread, every
// render sharing the process's one ThreadPool. After each pass a render publishes its progress (in memory for
// status requests, and to the store) and a preview PNG; at the end it writes the outputs the job asked for. A job
// that throws fails alone; the daemon stays up.
#pragma once

#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "renderer/scene_loader.h"
#include "renderer/thread_pool.h"
#include "server/job_files.h"
#include "server/job_store.h"

namespace tessera::server {

struct SchedulerOptions {
  int max_jobs = 1;
  RenderLimits limits;
  // How often the queue is looked at without being woken (jobs another process may have added).
  std::chrono::milliseconds poll_interval{1000};
};

class Scheduler {
 public:
  Scheduler(JobStore& store, const JobFiles& files, ThreadPool& pool, SchedulerOptions options);
  ~Scheduler();
  Scheduler(const Scheduler&) = delete;
  Scheduler& operator=(const Scheduler&) = delete;

  // Puts jobs a previous process left running back in the queue, then starts claiming.
  void start();
  // A job was queued: look at the queue now.
  void wake();
  // Stops claiming, cancels the running renders and puts their jobs back in the queue, and waits for the threads.
  void shutdown();
  bool accepting() const;

  // The progress of a job rendering here, fresher than the store's.
  std::optional<JobProgress> live_progress(const std::string& id) const;

  enum class CancelResult { kCancelled, kCancelling, kAlreadyFinished, kUnknown };
  CancelResult cancel(const std::string& id);
  // Deletes a job and its files (cancelling its render first); false for an unknown id.
  bool remove(const std::string& id);

 private:
  class RenderSlot;
  void dispatch_loop();
  void run_job(const std::shared_ptr<RenderSlot>& slot, const JobRecord& record);
  void reap_finished_locked(std::unique_lock<std::mutex>& lock);

  JobStore& store_;
  const JobFiles& files_;
  ThreadPool& pool_;
  SchedulerOptions options_;

  mutable std::mutex mutex_;
  std::condition_variable cv_;
  bool started_ = false;
  bool stopping_ = false;
  std::map<std::string, std::shared_ptr<RenderSlot>> running_;
  std::thread dispatcher_;
};

}  // namespace tessera::server
