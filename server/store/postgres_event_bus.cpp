#include "server/store/postgres_event_bus.h"

#include <chrono>

namespace tessera::server {

namespace {

// Rows read at once; a stream with more waiting reads the rest at its next wait, at once.
constexpr int kMaxRead = 1000;
// How often watchers read the store while its notifications are down.
constexpr std::chrono::milliseconds kPollWithoutNotifications{500};
// Notifications remembered for the watchers; a watcher that missed more reads its stream anyway.
constexpr size_t kRecentNotifications = 1024;

}  // namespace

PostgresEventBus::PostgresEventBus(const std::string& conninfo, const std::string& node,
                                   PostgresNotifications& notifications, size_t per_job_capacity, size_t total_capacity)
    : notifications_(notifications),
      per_job_capacity_(per_job_capacity),
      total_capacity_(total_capacity),
      conn_(conninfo, "tesserad " + node + " events") {
  notifications_.listen(kEventsChannel, [this](const std::string& payload) {
    if (auto parts = split_notification(payload)) notified(parts->second);
  });
  // What was published while the notifications were down: every watcher reads its stream again.
  notifications_.on_connected([this] { notified(""); });
}

void PostgresEventBus::notified(const std::string& job_id) {
  {
    std::lock_guard lock(mutex_);
    recent_.emplace_back(++generation_, job_id);
    while (recent_.size() > kRecentNotifications) recent_.pop_front();
  }
  cv_.notify_all();
}

bool PostgresEventBus::notified_since_locked(uint64_t seen, const std::string& job_id) const {
  if (generation_ == seen) return false;
  if (job_id.empty() || recent_.empty() || recent_.front().first > seen + 1) return true;
  for (auto it = recent_.rbegin(); it != recent_.rend() && it->first > seen; ++it)
    if (it->second.empty() || it->second == job_id) return true;
  return false;
}

void PostgresEventBus::publish(const std::string& job_id, const std::string& owner, const std::string& type,
                               const std::string& data, bool terminal) {
  std::lock_guard lock(conn_mutex_);
  conn_.exec("SELECT tessera_publish_event($1, $2, $3, $4, $5, $6, $7)",
             {job_id, owner, type, data, std::string(terminal ? "true" : "false"),
              pg_text(static_cast<int64_t>(per_job_capacity_)), pg_text(static_cast<int64_t>(total_capacity_))});
}

EventRead PostgresEventBus::read(const std::string& job_id, uint64_t after) {
  std::lock_guard lock(conn_mutex_);
  EventRead r;
  const std::string key = job_id;  // '' is the global stream's row
  PgResult head = conn_.exec(job_id.empty() ? "SELECT (SELECT last_seq FROM tessera_event_streams WHERE job_id = ''), "
                                              "(SELECT MIN(id) FROM tessera_events)"
                                            : "SELECT (SELECT last_seq FROM tessera_event_streams WHERE job_id = $1), "
                                              "(SELECT MIN(job_seq) FROM tessera_events WHERE job_id = $1)",
                             job_id.empty() ? PgConnection::Params{} : PgConnection::Params{key});
  r.last_seq = head.is_null(0) ? 0 : static_cast<uint64_t>(head.int64(0));
  // A client that knows of events this stream never had (ids of a stream since forgotten) gets the stream afresh.
  if (after > r.last_seq) after = 0;
  if (!head.is_null(1) && after > 0 && after + 1 < static_cast<uint64_t>(head.int64(1))) r.gap = true;
  const std::string limit = pg_text(static_cast<int64_t>(kMaxRead));
  PgResult rows = job_id.empty()
                      ? conn_.exec(
                            "SELECT id, type, job_id, owner, data, terminal FROM tessera_events WHERE id > $1 "
                            "ORDER BY id LIMIT $2",
                            {pg_text(static_cast<int64_t>(after)), limit})
                      : conn_.exec(
                            "SELECT job_seq, type, job_id, owner, data, terminal FROM tessera_events WHERE job_id = $1 "
                            "AND job_seq > $2 ORDER BY job_seq LIMIT $3",
                            {key, pg_text(static_cast<int64_t>(after)), limit});
  for (int i = 0; i < rows.rows(); ++i) {
    rows.at(i);
    r.events.push_back(JobEvent{static_cast<uint64_t>(rows.int64(0)), rows.text(1), rows.text(2), rows.text(3),
                                rows.text(4), rows.text(5) == "t"});
  }
  return r;
}

EventRead PostgresEventBus::wait(const std::string& job_id, uint64_t after, int timeout_ms) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  std::unique_lock lock(mutex_);
  ++watchers_;
  struct Leave {
    PostgresEventBus* bus;
    ~Leave() { --bus->watchers_; }  // under mutex_, held again by then
  } leave{this};
  for (;;) {
    const uint64_t seen = generation_;
    const bool closed = closed_;
    lock.unlock();
    EventRead r;
    try {
      r = read(job_id, after);
    } catch (...) {
      lock.lock();
      throw;
    }
    lock.lock();
    r.closed = closed;
    const auto now = std::chrono::steady_clock::now();
    if (closed || !r.events.empty() || r.gap || now >= deadline) return r;
    const auto until = notifications_.connected() ? deadline : std::min(deadline, now + kPollWithoutNotifications);
    cv_.wait_until(lock, until, [&] { return closed_ || notified_since_locked(seen, job_id); });
  }
}

uint64_t PostgresEventBus::last_seq(const std::string& job_id) {
  std::lock_guard lock(conn_mutex_);
  PgResult r = conn_.exec("SELECT last_seq FROM tessera_event_streams WHERE job_id = $1", {job_id});
  return r.rows() == 0 ? 0 : static_cast<uint64_t>(r.int64(0));
}

void PostgresEventBus::forget(const std::string& job_id) {
  if (job_id.empty()) return;
  std::lock_guard lock(conn_mutex_);
  conn_.exec("DELETE FROM tessera_events WHERE job_id = $1", {job_id});
  conn_.exec("DELETE FROM tessera_event_streams WHERE job_id = $1", {job_id});
}

void PostgresEventBus::close() {
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
  }
  cv_.notify_all();
}

size_t PostgresEventBus::watchers() const {
  std::lock_guard lock(mutex_);
  return watchers_;
}

}  // namespace tessera::server
