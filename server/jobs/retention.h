// Retention of finished jobs (--retain-finished): a thread of its own deletes the jobs that ended (succeeded, failed
// or cancelled) longer ago than the retention, through the same removal as DELETE /v1/jobs/{id} (remove_job(),
// http_api.h). Queued, running and paused jobs are never deleted: the store only removes a job that is still ended
// and old enough at the moment it is removed, and the scheduler keeps any job a render thread still holds.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "server/jobs/metrics.h"
#include "server/store/job_store.h"

namespace tessera::server {

class RetentionSweeper {
 public:
  // Deletes job `id` if it ended before `cutoff_ms` (Unix ms); true when it did.
  using RemoveExpired = std::function<bool(const std::string& id, int64_t cutoff_ms)>;

  // `retain_s` 0: finished jobs are kept forever and start() starts nothing.
  RetentionSweeper(JobStore& store, Metrics& metrics, int64_t retain_s, RemoveExpired remove);
  ~RetentionSweeper();
  RetentionSweeper(const RetentionSweeper&) = delete;
  RetentionSweeper& operator=(const RetentionSweeper&) = delete;

  // Sweeps at once (a daemon that was down a week catches up), then every period().
  void start();
  // Ends the thread within one deletion's time; idempotent.
  void stop();
  // One sweep as of `now_ms`; returns how many jobs it deleted. Never throws.
  int sweep(int64_t now_ms);

  // min(60 s, retention / 4), at least 1 s: a job outlives its retention by at most that.
  static std::chrono::milliseconds period(int64_t retain_s);

 private:
  bool stopping() const;

  JobStore& store_;
  Metrics& metrics_;
  const int64_t retain_s_;
  RemoveExpired remove_;

  mutable std::mutex mutex_;
  std::condition_variable cv_;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace tessera::server
