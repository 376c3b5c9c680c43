#include "server/store/postgres_notifications.h"

#include <libpq-fe.h>
#include <poll.h>

#include <cerrno>
#include <chrono>

#include "server/base/log.h"
#include "server/store/job_store.h"
#include "server/store/postgres_connection.h"

namespace tessera::server {

std::optional<std::pair<std::string, std::string>> split_notification(std::string_view payload) {
  const size_t space = payload.find(' ');
  if (space == std::string_view::npos || space == 0) return std::nullopt;
  return std::make_pair(std::string(payload.substr(0, space)), std::string(payload.substr(space + 1)));
}

PostgresNotifications::PostgresNotifications(std::string conninfo, std::string node)
    : conninfo_(std::move(conninfo)), node_(std::move(node)) {}

PostgresNotifications::~PostgresNotifications() {
  stop();
}

void PostgresNotifications::listen(const std::string& channel, Handler handler) {
  handlers_[channel].push_back(std::move(handler));
}

void PostgresNotifications::on_connected(std::function<void()> handler) {
  connected_handlers_.push_back(std::move(handler));
}

void PostgresNotifications::start() {
  if (thread_.joinable()) return;
  stop_ = false;
  thread_ = std::thread([this] { run(); });
}

void PostgresNotifications::stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

bool PostgresNotifications::sleep_unless_stopped(std::chrono::milliseconds d) {
  const auto until = std::chrono::steady_clock::now() + d;
  while (!stop_ && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(25));
  return !stop_;
}

void PostgresNotifications::run() {
  constexpr std::chrono::milliseconds kFirstRetry{100}, kMaxRetry{5000};
  std::chrono::milliseconds retry = kFirstRetry;
  while (!stop_) {
    try {
      listen_once();
    } catch (const std::exception& e) {
      if (connected_.exchange(false)) retry = kFirstRetry;
      // Logged once per outage, not at each attempt.
      if (!down_logged_)
        log(LogLevel::kWarn,
            "the store's notifications are down; polling it instead until they are back (changes made on other nodes "
            "arrive within about a second)",
            {{"error", e.what()}});
      down_logged_ = true;
    }
    if (!sleep_unless_stopped(retry)) break;
    retry = std::min(retry * 2, kMaxRetry);
  }
  connected_ = false;
}

// One connection's life: LISTEN to every channel, then hand over notifications until the connection breaks (throws)
// or the daemon stops (returns).
void PostgresNotifications::listen_once() {
  PgConnection conn(conninfo_, "tesserad " + node_ + " notifications");
  for (const auto& [channel, handlers] : handlers_) conn.exec("LISTEN " + channel);  // our own constant names
  connected_ = true;
  log(LogLevel::kInfo, "listening to the store's notifications");
  down_logged_ = false;
  for (const auto& handler : connected_handlers_) {
    try {
      handler();
    } catch (const std::exception& e) {
      log(LogLevel::kWarn, "cannot look at the store afresh after its notifications came back", {{"error", e.what()}});
    }
  }
  pg_conn* raw = conn.raw();
  while (!stop_) {
    pollfd fd{PQsocket(raw), POLLIN, 0};
    if (fd.fd < 0) throw JobStoreError("job store: the notification connection has no socket", false);
    const int ready = ::poll(&fd, 1, 250);
    if (ready < 0 && errno != EINTR) throw JobStoreError("job store: cannot wait for notifications", false);
    if (ready > 0 && !PQconsumeInput(raw)) {
      std::string msg = PQerrorMessage(raw);
      while (!msg.empty() && msg.back() == '\n') msg.pop_back();
      throw JobStoreError("job store: the notification connection broke: " + msg, false);
    }
    while (PGnotify* n = PQnotifies(raw)) {
      const std::string channel = n->relname, payload = n->extra;
      PQfreemem(n);
      auto it = handlers_.find(channel);
      if (it == handlers_.end()) continue;
      for (const auto& handler : it->second) {
        try {
          handler(payload);
        } catch (const std::exception& e) {
          log(LogLevel::kWarn, "cannot act on a notification of the store",
              {{"channel", channel}, {"payload", payload}, {"error", e.what()}});
        }
      }
    }
  }
}

}  // namespace tessera::server
