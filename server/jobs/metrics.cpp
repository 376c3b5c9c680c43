#include "server/jobs/metrics.h"

#include <charconv>
#include <cstdio>
#include <sstream>

namespace tessera::server {

namespace {

std::string number(double v) {
  char buf[64];
  auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);  // the shortest text that reads back as v
  return ec == std::errc() ? std::string(buf, end) : "0";
}

std::string label_value(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '\\' || c == '"') out += '\\';
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out += c;
  }
  return out;
}

}  // namespace

void Metrics::count_request(const std::string& route, int status) {
  std::lock_guard lock(mutex_);
  ++requests_[{route, status}];
}

bool Metrics::record_job_end(double seconds, const std::function<bool()>& record) {
  std::lock_guard lock(durations_mutex_);
  if (!record()) return false;
  for (size_t i = 0; i < kDurationBuckets.size(); ++i)
    if (seconds <= kDurationBuckets[i]) ++duration_buckets_[i];
  ++duration_count_;
  duration_sum_ += seconds;
  return true;
}

std::string Metrics::render(const Gauges& g) const {
  std::ostringstream out;
  if (!node_.empty())
    out << "# HELP tessera_node_info The daemon: its node name and job store.\n"
        << "# TYPE tessera_node_info gauge\n"
        << "tessera_node_info{node=\"" << label_value(node_) << "\",store=\"" << label_value(store_) << "\"} 1\n";
  out << "# HELP tessera_job_store_up Whether the job store works (0: it could not be read for this scrape, the end "
         "of a render waits for it to take a write, or it refused the last change a client asked for; as /readyz's "
         "job_store_failing).\n"
         "# TYPE tessera_job_store_up gauge\n"
      << "tessera_job_store_up " << (g.job_store_up ? 1 : 0) << "\n";
  if (g.store_notifications_up)
    out << "# HELP tessera_store_notifications_up Whether this node hears the other nodes' changes and events as they "
           "happen (PostgreSQL LISTEN); 0: it polls the store instead, and they reach it within about a second.\n"
           "# TYPE tessera_store_notifications_up gauge\n"
        << "tessera_store_notifications_up " << (*g.store_notifications_up ? 1 : 0) << "\n";
  if (g.jobs) {
    // Counts the store could not give are left out rather than reported as zero.
    out << "# HELP tessera_jobs Jobs in the store by state.\n# TYPE tessera_jobs gauge\n";
    for (const auto& [state, n] : *g.jobs)
      out << "tessera_jobs{state=\"" << job_state_name(state) << "\"} " << n << "\n";
    auto queued = g.jobs->find(JobState::kQueued);
    out << "# HELP tessera_queue_length Jobs waiting to be rendered.\n# TYPE tessera_queue_length gauge\n"
        << "tessera_queue_length " << (queued == g.jobs->end() ? 0 : queued->second) << "\n";
  }
  out << "# HELP tessera_samples_rendered_total Pixel samples rendered by this process.\n"
      << "# TYPE tessera_samples_rendered_total counter\n"
      << "tessera_samples_rendered_total " << samples_.load(std::memory_order_relaxed) << "\n";
  out << "# HELP tessera_render_threads Render threads of this process.\n# TYPE tessera_render_threads gauge\n"
      << "tessera_render_threads " << g.render_threads << "\n";
  out << "# HELP tessera_render_threads_busy Render threads working on a tile.\n"
      << "# TYPE tessera_render_threads_busy gauge\n"
      << "tessera_render_threads_busy " << g.render_threads_busy << "\n";
  out << "# HELP tessera_event_watchers Server-Sent Events streams waiting for events.\n"
      << "# TYPE tessera_event_watchers gauge\n"
      << "tessera_event_watchers " << g.event_watchers << "\n";
  if (g.http_connections) {
    out << "# HELP tessera_http_connections Open client connections.\n# TYPE tessera_http_connections gauge\n"
        << "tessera_http_connections " << *g.http_connections << "\n";
    out << "# HELP tessera_http_connections_refused_total Connections refused at accept: too many in all (503) or from "
           "one address (429), or an event stream beyond --max-event-streams (503).\n"
        << "# TYPE tessera_http_connections_refused_total counter\n"
        << "tessera_http_connections_refused_total " << g.http_refused_total.value_or(0) << "\n";
    out << "# HELP tessera_http_timeouts_total Request heads, bodies or responses that missed their deadline (408 or "
           "closed).\n# TYPE tessera_http_timeouts_total counter\n"
        << "tessera_http_timeouts_total " << g.http_timed_out_total.value_or(0) << "\n";
  }
  out << "# HELP tessera_jobs_expired_total Finished jobs deleted by the retention sweep (--retain-finished).\n"
      << "# TYPE tessera_jobs_expired_total counter\n"
      << "tessera_jobs_expired_total " << expired_jobs_.load(std::memory_order_relaxed) << "\n";
  out << "# HELP tessera_job_store_errors_total Operations on the job store that failed: requests answered 503 or 507 "
         "because of it, event streams it ended, scrapes it could not count, and writes of renders (progress, "
         "warnings, the end of a job; an end is retried until it is recorded).\n"
      << "# TYPE tessera_job_store_errors_total counter\n"
      << "tessera_job_store_errors_total " << job_store_errors_.load(std::memory_order_relaxed) << "\n";
  if (g.data_dir_available_bytes)
    out << "# HELP tessera_data_dir_available_bytes Bytes available to the daemon on the data directory's "
           "filesystem.\n"
        << "# TYPE tessera_data_dir_available_bytes gauge\n"
        << "tessera_data_dir_available_bytes " << *g.data_dir_available_bytes << "\n";
  out << "# HELP tessera_min_free_disk_bytes Available bytes below which new jobs and uploads are refused "
         "(--min-free-disk; 0: never).\n"
      << "# TYPE tessera_min_free_disk_bytes gauge\n"
      << "tessera_min_free_disk_bytes " << g.min_free_disk_bytes << "\n";
  {
    std::lock_guard lock(durations_mutex_);
    out << "# HELP tessera_job_duration_seconds Render time of jobs that ended (succeeded, failed or cancelled).\n"
        << "# TYPE tessera_job_duration_seconds histogram\n";
    for (size_t i = 0; i < kDurationBuckets.size(); ++i)
      out << "tessera_job_duration_seconds_bucket{le=\"" << number(kDurationBuckets[i]) << "\"} "
          << duration_buckets_[i] << "\n";
    out << "tessera_job_duration_seconds_bucket{le=\"+Inf\"} " << duration_count_ << "\n"
        << "tessera_job_duration_seconds_sum " << number(duration_sum_) << "\n"
        << "tessera_job_duration_seconds_count " << duration_count_ << "\n";
  }
  std::lock_guard lock(mutex_);
  out << "# HELP tessera_http_requests_total HTTP requests answered, by route pattern and status code.\n"
      << "# TYPE tessera_http_requests_total counter\n";
  for (const auto& [key, n] : requests_)
    out << "tessera_http_requests_total{route=\"" << label_value(key.first) << "\",code=\"" << key.second << "\"} " << n
        << "\n";
  return out.str();
}

}  // namespace tessera::server
