// The daemon's metrics in the Prometheus text format (0.0.4): counters and a histogram kept in memory, gauges read
// when scraped. Labels are bounded sets (state, route pattern, status code); never a job id.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>

#include "server/store/job_state.h"

namespace tessera::server {

class Metrics {
 public:
  Metrics() = default;
  // The daemon's node name and store ("sqlite", "postgresql"): tessera_node_info{node, store} 1, so that the metrics
  // of several daemons on one store tell which daemon they come from.
  Metrics(std::string node, std::string store) : node_(std::move(node)), store_(std::move(store)) {}

  void count_request(const std::string& route, int status);
  void add_samples(uint64_t pixel_samples) { samples_.fetch_add(pixel_samples, std::memory_order_relaxed); }
  // The end of a job and its render time in one step: `record` (the job store's state change; true when the store
  // took it) runs under the histogram's lock, and the time is counted when it took. A scrape waits for a step under
  // way, so once a reader can see a job ended, /metrics counts it.
  bool record_job_end(double seconds, const std::function<bool()>& record);
  void count_expired_job() { expired_jobs_.fetch_add(1, std::memory_order_relaxed); }
  void count_job_store_error() { job_store_errors_.fetch_add(1, std::memory_order_relaxed); }

  struct Gauges {
    std::optional<std::map<JobState, int>> jobs;  // nothing when the store could not be read (left out, not zero)
    bool job_store_up = true;  // false: the store failed to be read, or the end of a render waits for it
    int render_threads = 0;
    int render_threads_busy = 0;
    size_t event_watchers = 0;
    std::optional<bool> store_notifications_up;  // nothing on a store without notifications
    // The connection layer's, when the daemon serves through it: open connections, connections refused at accept
    // (429, 503) and requests or transfers that missed a deadline.
    std::optional<int64_t> http_connections, http_refused_total, http_timed_out_total;
    std::optional<uint64_t> data_dir_available_bytes;  // nothing when the filesystem cannot be asked
    uint64_t min_free_disk_bytes = 0;
  };
  std::string render(const Gauges& g) const;

  static constexpr std::array<double, 12> kDurationBuckets = {0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 300, 1800, 7200};

 private:
  std::string node_, store_;
  mutable std::mutex mutex_;
  std::map<std::pair<std::string, int>, uint64_t> requests_;
  mutable std::mutex durations_mutex_;  // the histogram's; held across a job's end (record_job_end)
  std::array<uint64_t, kDurationBuckets.size()> duration_buckets_{};
  uint64_t duration_count_ = 0;
  double duration_sum_ = 0;
  std::atomic<uint64_t> samples_{0};
  std::atomic<uint64_t> expired_jobs_{0};
  std::atomic<uint64_t> job_store_errors_{0};
};

}  // namespace tessera::server
