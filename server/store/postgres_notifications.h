// What crosses the nodes of one PostgreSQL store as it happens: one dedicated connection per daemon that LISTENs
// (PostgreSQL 15 documentation, "LISTEN" and "NOTIFY"; libpq's "Asynchronous Notification"), waiting on its socket
// with a timeout, and hands each notification to the handler of its channel on its own thread. The channels and
// their payloads are the schema's (PostgresJobStore's migration 3): kJobsChannel carries "ID STATE" of a job added,
// deleted or changed, kEventsChannel "ID JOB" of an event published for clients.
// A notification is sent when its transaction commits and only to connections listening then: one that broke loses
// what was sent meanwhile. So the connection is opened again (after 0.1 s, doubling up to 5 s) and, once it listens
// again, the `on_connected` handlers run, to look at the store afresh; while it is down, connected() is false and
// the daemon falls back to polling the store (the scheduler's lease renewals and claims every second, the event
// streams' reads every half second).
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace tessera::server {

inline constexpr const char* kJobsChannel = "tessera_jobs";
inline constexpr const char* kEventsChannel = "tessera_events";

// A payload "WORD REST" split at its first space (a job notification: the id and its state or "deleted"; an event
// notification: its id and its job); nothing when there is no space.
std::optional<std::pair<std::string, std::string>> split_notification(std::string_view payload);

class PostgresNotifications {
 public:
  using Handler = std::function<void(const std::string& payload)>;

  // `node` names its connection (pg_stat_activity).
  PostgresNotifications(std::string conninfo, std::string node);
  ~PostgresNotifications();
  PostgresNotifications(const PostgresNotifications&) = delete;
  PostgresNotifications& operator=(const PostgresNotifications&) = delete;

  // Before start(): the handler of a channel's notifications, and what runs each time the connection listens (again).
  // Handlers run on the listening thread, one at a time; one that throws is logged.
  void listen(const std::string& channel, Handler handler);
  void on_connected(std::function<void()> handler);
  void start();
  // Stops listening and waits for the thread (within a quarter of a second).
  void stop();
  // Listening now: notifications arrive. False before the first connection and while it is down.
  bool connected() const { return connected_.load(); }

 private:
  void run();
  void listen_once();
  bool sleep_unless_stopped(std::chrono::milliseconds d);

  std::string conninfo_;
  std::string node_;
  std::map<std::string, std::vector<Handler>> handlers_;
  std::vector<std::function<void()>> connected_handlers_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> connected_{false};
  bool down_logged_ = false;  // the listening thread's own
  std::thread thread_;
};

}  // namespace tessera::server
