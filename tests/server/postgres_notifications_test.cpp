// What crosses the nodes of one PostgreSQL store as it happens: the jobs' changes made through one store are heard by
// another node's notification connection (cancel, pause, delete, priority, claims, new jobs), also after the server
// restarted; events published on one node are read on another, in one numbering, with the retention and the gaps of
// the in-memory bus, and without notifications they are read by polling.
#include <gtest/gtest.h>

#include <mutex>
#include <thread>

#include "server/store/postgres_event_bus.h"
#include "server/store/postgres_job_store.h"
#include "server/store/postgres_notifications.h"
#include "tests/server/postgres_cluster.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using test::eventually;
using test::make_job;
using test::PostgresCluster;

// The payloads one node hears on a channel.
class Heard {
 public:
  Heard(PostgresNotifications& n, const char* channel) {
    n.listen(channel, [this](const std::string& payload) {
      std::lock_guard lock(mutex_);
      payloads_.push_back(payload);
    });
  }
  bool has(const std::string& payload) const {
    std::lock_guard lock(mutex_);
    return std::find(payloads_.begin(), payloads_.end(), payload) != payloads_.end();
  }
  size_t count() const {
    std::lock_guard lock(mutex_);
    return payloads_.size();
  }

 private:
  mutable std::mutex mutex_;
  std::vector<std::string> payloads_;
};

TEST(PostgresNotifications, ANodeHearsTheJobChangesMadeThroughAnother) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  PostgresJobStore a(uri, "node-a");
  PostgresNotifications b(uri, "node-b");
  Heard heard(b, kJobsChannel);
  b.start();
  ASSERT_TRUE(eventually([&] { return b.connected(); }, 10));
  // Each connection says whose and what it is, for the operator's pg_stat_activity.
  EXPECT_EQ(pg.psql(PostgresCluster::database_of(uri),
                    "SELECT string_agg(application_name, ',' ORDER BY application_name) FROM pg_stat_activity "
                    "WHERE application_name LIKE 'tesserad%'"),
            "tesserad node-a,tesserad node-b notifications");
  const JobRecord j = make_job(0, 1);
  a.create(j);
  EXPECT_TRUE(eventually([&] { return heard.has(j.id + " queued"); }, 5));
  const JobRecord claimed = a.claim_next(2).value();
  EXPECT_TRUE(eventually([&] { return heard.has(j.id + " running"); }, 5));
  // Progress and lease renewals are no news: only state, priority and epoch are.
  const size_t before = heard.count();
  ASSERT_TRUE(a.update_progress(j.id, claimed.epoch, JobProgress{}));
  ASSERT_TRUE(a.renew_lease(j.id, claimed.epoch, 3, 1000));
  ASSERT_TRUE(a.set_priority(j.id, 7));
  EXPECT_TRUE(eventually([&] { return heard.count() == before + 1; }, 5));
  ASSERT_TRUE(a.transition(j.id, JobState::kCancelled, 4, "cancelled", ""));
  EXPECT_TRUE(eventually([&] { return heard.has(j.id + " cancelled"); }, 5));
  ASSERT_TRUE(a.remove(j.id));
  EXPECT_TRUE(eventually([&] { return heard.has(j.id + " deleted"); }, 5));
  EXPECT_EQ(heard.count(), before + 3);
  EXPECT_EQ(split_notification(j.id + " deleted"), std::make_pair(j.id, std::string("deleted")));
  EXPECT_FALSE(split_notification("nospace"));
}

// The server restarted: the connection is opened again, `on_connected` runs again (what was notified meanwhile is
// lost: the daemon looks at the store afresh), and notifications arrive again.
TEST(PostgresNotifications, ListenAgainAfterTheServerRestarted) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  PostgresJobStore a(uri, "node-a");
  PostgresNotifications b(uri, "node-b");
  Heard heard(b, kJobsChannel);
  std::atomic<int> connections{0};
  b.on_connected([&] { ++connections; });
  b.start();
  ASSERT_TRUE(eventually([&] { return connections == 1 && b.connected(); }, 10));
  pg.restart();
  ASSERT_TRUE(eventually([&] { return connections == 2 && b.connected(); }, 20));
  const JobRecord j = make_job(0, 1);
  for (int attempt = 0; attempt < 2; ++attempt) {
    try {
      a.create(j);  // the store's own connection finds the restart first
      break;
    } catch (const JobStoreError&) {
    }
  }
  EXPECT_TRUE(eventually([&] { return heard.has(j.id + " queued"); }, 5));
}

// A node's bus and its notification connection.
struct Node {
  explicit Node(const std::string& uri, size_t per_job = 256, size_t total = 65536, bool listen = true)
      : notifications(uri, "node"), bus(uri, "node", notifications, per_job, total) {
    if (listen) notifications.start();
  }
  PostgresNotifications notifications;
  PostgresEventBus bus;
};

std::vector<uint64_t> seqs(const EventRead& r) {
  std::vector<uint64_t> out;
  for (const JobEvent& e : r.events) out.push_back(e.seq);
  return out;
}

TEST(PostgresEventBus, EventsPublishedOnOneNodeAreStreamedFromAnother) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  PostgresJobStore schema(uri, "migrations");
  Node a(uri), b(uri);
  ASSERT_TRUE(eventually([&] { return a.notifications.connected() && b.notifications.connected(); }, 10));
  // A watcher on b is woken by a's event (well before its minute is over).
  EventRead woken;
  std::thread watcher([&] { woken = b.bus.wait("job-1", 0, 60000); });
  ASSERT_TRUE(eventually([&] { return b.bus.watchers() == 1; }, 5));
  const auto published_at = std::chrono::steady_clock::now();
  a.bus.publish("job-1", "alice", "state", R"({"state":"running"})");
  watcher.join();
  EXPECT_LT(std::chrono::steady_clock::now() - published_at, std::chrono::seconds(30));
  ASSERT_EQ(woken.events.size(), 1u);
  EXPECT_EQ(woken.events[0].seq, 1u);
  EXPECT_EQ(woken.events[0].owner, "alice");
  EXPECT_EQ(woken.events[0].data, R"({"state":"running"})");
  EXPECT_FALSE(woken.events[0].terminal);

  a.bus.publish("job-2", "bob", "progress", "{}");
  b.bus.publish("job-1", "alice", "progress", "{}");
  a.bus.publish("job-1", "alice", "state", R"({"state":"succeeded"})", true);
  // Each job's stream counts its own events, the global one every event, whichever node published them.
  EXPECT_EQ(a.bus.last_seq("job-1"), 3u);
  EXPECT_EQ(b.bus.last_seq("job-2"), 1u);
  EXPECT_EQ(b.bus.last_seq(""), 4u);
  EXPECT_EQ(b.bus.last_seq("no-such-job"), 0u);
  // Last-Event-ID on any node: the events after it.
  const EventRead replay = b.bus.wait("job-1", 1, 0);
  EXPECT_EQ(seqs(replay), (std::vector<uint64_t>{2, 3}));
  EXPECT_TRUE(replay.events.back().terminal);
  EXPECT_FALSE(replay.gap);
  EXPECT_EQ(replay.last_seq, 3u);
  EXPECT_EQ(seqs(a.bus.wait("", 2, 0)), (std::vector<uint64_t>{3, 4}));
  EXPECT_EQ(a.bus.wait("", 2, 0).events[0].job_id, "job-1");
  // Ids this stream never had: the stream afresh.
  EXPECT_EQ(seqs(a.bus.wait("job-2", 9, 0)), (std::vector<uint64_t>{1}));
  // Nothing new: the wait times out empty.
  EXPECT_TRUE(b.bus.wait("job-1", 3, 100).events.empty());
  // A deleted job's stream goes.
  a.bus.forget("job-1");
  EXPECT_EQ(b.bus.last_seq("job-1"), 0u);
  EXPECT_TRUE(b.bus.wait("job-1", 0, 0).events.empty());
  EXPECT_EQ(seqs(b.bus.wait("", 0, 0)), (std::vector<uint64_t>{2}));
  // Shutting down wakes the watchers.
  std::thread closing([&] { woken = b.bus.wait("job-3", 0, 60000); });
  ASSERT_TRUE(eventually([&] { return b.bus.watchers() == 1; }, 5));
  b.bus.close();
  closing.join();
  EXPECT_TRUE(woken.closed);
}

// Bounded: the newest events of each job, and of all; a client that asks for more than is kept is told (a gap).
TEST(PostgresEventBus, KeepsTheNewestEventsAndSaysWhenSomeAreGone) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  PostgresJobStore schema(uri, "migrations");
  Node a(uri, 4, 6);
  for (int i = 0; i < 10; ++i) a.bus.publish("job-1", "", "progress", "{}");
  EventRead r = a.bus.wait("job-1", 0, 0);
  EXPECT_EQ(seqs(r), (std::vector<uint64_t>{7, 8, 9, 10}));
  EXPECT_TRUE(a.bus.wait("job-1", 2, 0).gap);
  EXPECT_FALSE(a.bus.wait("job-1", 6, 0).gap);
  for (int i = 0; i < 4; ++i) a.bus.publish("job-2", "", "progress", "{}");
  EXPECT_EQ(seqs(a.bus.wait("", 0, 0)), (std::vector<uint64_t>{9, 10, 11, 12, 13, 14}));
  EXPECT_EQ(pg.psql(PostgresCluster::database_of(uri), "SELECT COUNT(*) FROM tessera_events"), "6");
}

// Without notifications (their connection down), a watcher still gets the events, by reading the store every half
// second.
TEST(PostgresEventBus, WithoutNotificationsWatchersPollTheStore) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  PostgresJobStore schema(uri, "migrations");
  Node a(uri), deaf(uri, 256, 65536, false);
  ASSERT_FALSE(deaf.notifications.connected());
  EventRead got;
  std::thread watcher([&] { got = deaf.bus.wait("job-1", 0, 20000); });
  ASSERT_TRUE(eventually([&] { return deaf.bus.watchers() == 1; }, 5));
  const auto published_at = std::chrono::steady_clock::now();
  a.bus.publish("job-1", "", "state", "{}");
  watcher.join();
  EXPECT_EQ(seqs(got), (std::vector<uint64_t>{1}));
  EXPECT_LT(std::chrono::steady_clock::now() - published_at, std::chrono::seconds(10));
}

}  // namespace
}  // namespace tessera::server
