#include "server/jobs/retention.h"

#include <algorithm>
#include <exception>
#include <vector>

#include "server/base/log.h"
#include "server/base/time_format.h"

namespace tessera::server {

RetentionSweeper::RetentionSweeper(JobStore& store, Metrics& metrics, int64_t retain_s, RemoveExpired remove)
    : store_(store), metrics_(metrics), retain_s_(retain_s), remove_(std::move(remove)) {}

RetentionSweeper::~RetentionSweeper() {
  stop();
}

std::chrono::milliseconds RetentionSweeper::period(int64_t retain_s) {
  const int64_t quarter_ms = retain_s * 1000 / 4;
  return std::chrono::milliseconds(std::clamp<int64_t>(quarter_ms, 1000, 60000));
}

void RetentionSweeper::start() {
  if (retain_s_ <= 0 || thread_.joinable()) return;
  log(LogLevel::kInfo, "finished jobs are deleted after the retention",
      {{"retain_finished_s", retain_s_}, {"sweep_period_s", period(retain_s_).count() / 1000.0}});
  thread_ = std::thread([this] {
    std::unique_lock lock(mutex_);
    while (!stopping_) {
      lock.unlock();
      sweep(now_ms());
      lock.lock();
      cv_.wait_for(lock, period(retain_s_), [this] { return stopping_; });
    }
  });
}

void RetentionSweeper::stop() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

bool RetentionSweeper::stopping() const {
  std::lock_guard lock(mutex_);
  return stopping_;
}

int RetentionSweeper::sweep(int64_t now_ms) {
  const int64_t cutoff_ms = now_ms - retain_s_ * 1000;
  int deleted = 0;
  try {
    JobFilter filter;
    for (JobState s : kAllJobStates)
      if (is_terminal(s)) filter.states.push_back(s);
    filter.finished_before_ms = cutoff_ms;
    filter.limit = 100;
    // Page by submission order: a job that could not be deleted now (still held by its render thread) is not
    // listed again in this sweep.
    for (;;) {
      const std::vector<JobRecord> page = store_.list(filter);
      for (const JobRecord& job : page) {
        if (stopping()) return deleted;
        if (!remove_(job.id, cutoff_ms)) continue;
        ++deleted;
        metrics_.count_expired_job();
        log(LogLevel::kInfo, "finished job expired",
            {{"job", job.id},
             {"state", job_state_name(job.state)},
             {"finished_at", job.finished_at_ms ? rfc3339_ms(*job.finished_at_ms) : ""},
             {"retain_finished_s", retain_s_}});
      }
      if (static_cast<int>(page.size()) < filter.limit) break;
      filter.before_seq = page.back().seq;
    }
  } catch (const std::exception& e) {
    log(LogLevel::kError, "retention sweep failed; retried at the next one", {{"error", e.what()}});
  }
  return deleted;
}

}  // namespace tessera::server
