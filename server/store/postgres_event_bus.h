// The event bus of daemons sharing a PostgreSQL store: every event is a row (tessera_events, PostgresJobStore's
// migration 3), so a client streaming from any node sees the events of a job rendering on any other, and a reconnect
// with Last-Event-ID continues on whichever node it reaches. Publishing is one statement (tessera_publish_event:
// numbered in commit order, the oldest rows dropped past the retention, a NOTIFY of the new id and its job). Watchers
// wait for the notification of their stream (PostgresNotifications), then read the rows after their last id; while
// the notifications are down they read every half second instead. The streams' ids and gaps mean what EventHub's do.
#pragma once

#include <condition_variable>
#include <deque>
#include <mutex>

#include "server/files/events.h"
#include "server/store/postgres_connection.h"
#include "server/store/postgres_notifications.h"

namespace tessera::server {

class PostgresEventBus final : public EventBus {
 public:
  // Listens to kEventsChannel through `notifications` (before it starts). Keeps the newest `per_job_capacity` events
  // of each job and `total_capacity` in all. `node` names its connection.
  PostgresEventBus(const std::string& conninfo, const std::string& node, PostgresNotifications& notifications,
                   size_t per_job_capacity = 256, size_t total_capacity = 65536);

  void publish(const std::string& job_id, const std::string& owner, const std::string& type, const std::string& data,
               bool terminal = false) override;
  EventRead wait(const std::string& job_id, uint64_t after, int timeout_ms) override;
  uint64_t last_seq(const std::string& job_id) override;
  void forget(const std::string& job_id) override;
  void close() override;
  size_t watchers() const override;

 private:
  // The events of a stream after `after`, as EventHub::wait() reads them (without `closed`).
  EventRead read(const std::string& job_id, uint64_t after);
  // Whether a notification for the stream of `job_id` (any, for the global stream) came after generation `seen`.
  bool notified_since_locked(uint64_t seen, const std::string& job_id) const;
  void notified(const std::string& job_id);

  PostgresNotifications& notifications_;
  const size_t per_job_capacity_, total_capacity_;

  std::mutex conn_mutex_;
  PgConnection conn_;

  mutable std::mutex mutex_;
  std::condition_variable cv_;
  uint64_t generation_ = 0;  // notifications received
  // The jobs of the latest notifications, with their generation; an empty job means "any" (after a reconnection).
  std::deque<std::pair<uint64_t, std::string>> recent_;
  bool closed_ = false;
  size_t watchers_ = 0;
};

}  // namespace tessera::server
