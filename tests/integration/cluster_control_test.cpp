// Daemons sharing one PostgreSQL store and one data directory, driven as a client would: a cancel, pause or delete
// made through one node stops the render on the node that runs it within a second (the store's notification, not
// the next lease renewal); a client streaming a job's events from one node sees the progress of its render on
// another, and a reconnect with Last-Event-ID on a third continues where it left off; PostgreSQL restarted mid-render:
// the nodes reconnect, their renders end as they would have, none is claimed twice, and control crosses nodes again.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <functional>
#include <optional>
#include <sstream>
#include <thread>

#include "tests/integration/daemon.h"
#include "tests/integration/postgres_nodes.h"
#include "tests/server/postgres_cluster.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;

std::vector<std::string> node_args(const std::string& uri, const std::string& name) {
  return {"--store", uri, "--node", name, "--threads", "1", "--keepalive-s", "1"};
}

// Whether the daemon's log says that its render of `id` stopped because the job changed elsewhere.
bool render_stopped(const Daemon& d, const std::string& id) {
  std::istringstream log(d.log());
  for (std::string line; std::getline(log, line);)
    if (line.find("render stopped: the job was changed") != std::string::npos && line.find(id) != std::string::npos)
      return true;
  return false;
}

// Submits a long job through `a`, waits until one of the nodes has rendered it or one of its units for 3 s (its passes
// then take about 2 s each: its next progress write is no quicker way to learn of the change than a renewal), then
// makes `action` ("cancel", "pause" or "delete") through the other node. The seconds from that node's answer to the
// render's stop on the node that ran it (nothing when it did not stop within 10 s).
std::optional<double> stop_through_the_other_node(PostgresCluster& pg, const std::string& uri, Daemon& a,
                                                  const std::string& a_name, Daemon& b, const std::string& action,
                                                  std::string* id_out = nullptr) {
  auto ca = a.client();
  const std::string id = submit(*ca, long_cornell_job());
  if (id_out) *id_out = id;
  std::string node;
  if (!eventually(
          [&] {
            // A node rendering the job whole, or one of its work units (a long job is split among the nodes).
            node = pg.psql(PostgresCluster::database_of(uri),
                           "SELECT node FROM tessera_jobs WHERE id = '" + id +
                               "' AND state = 'running' AND units = 1 AND elapsed_s >= 3 UNION ALL SELECT node FROM "
                               "tessera_units WHERE job_id = '" +
                               id + "' AND state = 'running' AND elapsed_s >= 3 LIMIT 1");
            return !node.empty();
          },
          60)) {
    ADD_FAILURE() << "the job did not start";
    return std::nullopt;
  }
  Daemon& renderer = node == a_name ? a : b;
  Daemon& other = node == a_name ? b : a;
  auto c = other.client();
  auto res = action == "delete" ? c->Delete("/v1/jobs/" + id) : c->Post("/v1/jobs/" + id + "/" + action);
  if (!res || res->status >= 300) {
    ADD_FAILURE() << action << " refused: " << (res ? res->body : "no answer");
    return std::nullopt;
  }
  const auto answered = std::chrono::steady_clock::now();
  while (!render_stopped(renderer, id)) {
    if (std::chrono::steady_clock::now() - answered > std::chrono::seconds(10)) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - answered).count();
  // Told by the store as the change committed, not found at its next lease renewal or progress write (those are the
  // fallback while notifications are down, up to a second or a pass later).
  std::istringstream log(renderer.log());
  bool notified = false;
  for (std::string line; std::getline(log, line);)
    if (line.find("changed or taken over elsewhere; its render here stops") != std::string::npos &&
        line.find(id) != std::string::npos)
      notified = line.find("\"noticed_by\":\"the store's notification\"") != std::string::npos;
  EXPECT_TRUE(notified) << renderer.log();
  std::printf("%s through %s of a job rendering on %s: the render stopped %.3f s after the answer\n", action.c_str(),
              node == a_name ? "node-b" : a_name.c_str(), node.c_str(), s);
  return s;
}

TEST(Cluster, CancelPauseAndDeleteThroughOneNodeStopTheRenderOnAnotherWithinASecond) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  TempDir dir;
  Daemon a(dir.path() / "shared", node_args(uri, "node-a")), b(dir.path() / "shared", node_args(uri, "node-b"));
  auto ca = a.client(), cb = b.client();
  for (const std::string action : {"cancel", "pause", "delete", "cancel"}) {
    SCOPED_TRACE(action);
    std::string id;
    const auto s = stop_through_the_other_node(pg, uri, a, "node-a", b, action, &id);
    ASSERT_TRUE(s) << "the render did not stop within 10 s\n" << a.log() << b.log();
    EXPECT_LT(*s, 1.0);
    // What the client asked for stands, seen from either node: the render wrote nothing over it.
    const std::string expected = action == "cancel" ? "cancelled" : action == "pause" ? "paused" : "";
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    EXPECT_EQ(state_of(*ca, id), expected);
    EXPECT_EQ(state_of(*cb, id), expected);
    if (action == "pause") {  // resumed, it goes on from its checkpoint: nothing lost by stopping it elsewhere
      auto res = cb->Post("/v1/jobs/" + id + "/resume");
      ASSERT_TRUE(res && res->status < 300);
      ASSERT_TRUE(eventually([&] { return state_of(*ca, id) == "running"; }, 30));
      ASSERT_TRUE(ca->Post("/v1/jobs/" + id + "/cancel"));
      ASSERT_TRUE(eventually([&] { return state_of(*ca, id) == "cancelled"; }, 30));
    }
  }
  EXPECT_EQ(a.log().find("job succeeded"), std::string::npos);
  EXPECT_EQ(b.log().find("job succeeded"), std::string::npos);
}

struct SseEvent {
  uint64_t id = 0;
  std::string type;
  json data;
};

// Reads the event stream at `path` (from `last_id` on, when given) until `enough`, the stream ends, or 30 s have
// passed (the daemons send a keep-alive every second: --keepalive-s 1).
std::vector<SseEvent> read_events(httplib::Client& c, const std::string& path, std::optional<uint64_t> last_id,
                                  const std::function<bool(const std::vector<SseEvent>&)>& enough) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  httplib::Headers headers;
  if (last_id) headers.emplace("Last-Event-ID", std::to_string(*last_id));
  std::string buffer;
  std::vector<SseEvent> events;
  c.Get(path, headers, [&](const char* data, size_t n) {
    buffer.append(data, n);
    for (size_t end; (end = buffer.find("\n\n")) != std::string::npos;) {
      const std::string block = buffer.substr(0, end);
      buffer.erase(0, end + 2);
      SseEvent e;
      size_t from = 0;
      while (from < block.size()) {
        size_t eol = block.find('\n', from);
        if (eol == std::string::npos) eol = block.size();
        const std::string line = block.substr(from, eol - from);
        if (line.rfind("id: ", 0) == 0) e.id = std::stoull(line.substr(4));
        if (line.rfind("event: ", 0) == 0) e.type = line.substr(7);
        if (line.rfind("data: ", 0) == 0) e.data = json::parse(line.substr(6));
        from = eol + 1;
      }
      if (!e.type.empty()) events.push_back(e);
    }
    return !enough(events) && std::chrono::steady_clock::now() < deadline;
  });
  return events;
}

size_t count_of(const std::vector<SseEvent>& events, const std::string& type) {
  return static_cast<size_t>(
      std::count_if(events.begin(), events.end(), [&](const auto& e) { return e.type == type; }));
}

TEST(Cluster, EventsOfAJobRenderingOnOneNodeStreamFromAnotherAndReplayOnAThird) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  TempDir dir;
  const auto shared = dir.path() / "shared";
  Daemon b(shared, node_args(uri, "node-b"));
  auto cb = b.client();
  const std::string id = submit(*cb, cornell_job(64, 512));
  ASSERT_TRUE(eventually([&] { return row_of(pg, uri, id, "state || ',' || node") == "running,node-b"; }, 30));
  // The other nodes start once node-b holds the job: they can only serve it.
  Daemon a(shared, node_args(uri, "node-a")), c(shared, node_args(uri, "node-c"));
  auto ca = a.client(), cc = c.client();
  const std::string path = "/v1/jobs/" + id + "/events";
  const auto on_a = read_events(*ca, path, std::nullopt, [](const auto& e) { return count_of(e, "progress") >= 2; });
  ASSERT_GE(count_of(on_a, "progress"), 2u) << "node-a streamed no progress of a render on node-b\n" << b.log();
  EXPECT_EQ(on_a.front().type, "state");  // the job as it is, first
  EXPECT_EQ(on_a.front().data.value("state", ""), "running");
  for (size_t i = 1; i < on_a.size(); ++i) EXPECT_EQ(on_a[i].id, on_a[i - 1].id + 1);
  // node-a's stream dropped after its first progress event; the client reconnects to node-c with the id of it.
  size_t first_progress = 0;
  while (on_a[first_progress].type != "progress") ++first_progress;
  const uint64_t last_seen = on_a[first_progress].id;
  const auto on_c = read_events(*cc, path, last_seen, [](const auto&) { return false; });  // to its end
  ASSERT_FALSE(on_c.empty());
  EXPECT_EQ(on_c.front().id, last_seen + 1);
  EXPECT_EQ(on_c.front().type, on_a[first_progress + 1].type);
  EXPECT_EQ(on_c.front().data, on_a[first_progress + 1].data);  // the very event node-a sent next
  for (size_t i = 1; i < on_c.size(); ++i) EXPECT_EQ(on_c[i].id, on_c[i - 1].id + 1);
  EXPECT_EQ(on_c.back().type, "state");
  EXPECT_EQ(on_c.back().data.value("state", ""), "succeeded");
  // Progress counts up to the job's samples: the render's own figures, seen from a node that did not render it.
  uint64_t done = 0;
  for (const SseEvent& e : on_c)
    if (e.type == "progress") {
      const uint64_t now = e.data["progress"].value("samples_done", 0u);
      EXPECT_GE(now, done);
      done = now;
    }
  EXPECT_GT(done, 0u);
  // The global stream too: any node replays it from an id.
  const auto global =
      read_events(*cc, "/v1/events?last_event_id=1", std::nullopt, [](const auto& e) { return !e.empty(); });
  ASSERT_FALSE(global.empty());
  EXPECT_EQ(global.front().id, 2u);
}

TEST(Cluster, PostgresRestartedMidRenderTheNodesReconnectAndLoseNothing) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  TempDir dir;
  const auto shared = dir.path() / "shared";
  Daemon a(shared, node_args(uri, "node-a")), b(shared, node_args(uri, "node-b"));
  auto ca = a.client(), cb = b.client();
  std::vector<std::string> ids;
  for (int i = 0; i < 6; ++i) ids.push_back(submit(i % 2 ? *cb : *ca, cornell_job(48, 256)));
  ASSERT_TRUE(eventually(
      [&] {
        return pg.psql(PostgresCluster::database_of(uri),
                       "SELECT COUNT(*) FROM tessera_jobs WHERE state = 'running' AND passes >= 1") == "2";
      },
      60));
  pg.restart();
  const auto count_of_state = [&](const std::string& state) {
    return pg.psql(PostgresCluster::database_of(uri),
                   "SELECT COUNT(*) FROM tessera_jobs WHERE state = '" + state + "'");
  };
  ASSERT_TRUE(eventually([&] { return count_of_state("succeeded") == "6"; }, 180))
      << pg.psql(PostgresCluster::database_of(uri), "SELECT state, node, epoch FROM tessera_jobs") << a.log()
      << b.log();
  // None claimed twice, every one answered by either node.
  EXPECT_EQ(pg.psql(PostgresCluster::database_of(uri), "SELECT COUNT(*) FROM tessera_jobs WHERE epoch <> 1"), "0");
  for (const std::string& id : ids) {
    EXPECT_EQ(state_of(*ca, id), "succeeded");
    EXPECT_EQ(state_of(*cb, id), "succeeded");
  }
  // Both listen again, and control crosses nodes as before.
  auto listenings = [](const std::string& log) {
    size_t n = 0;
    for (size_t at = log.find("listening to the store's notifications"); at != std::string::npos;
         at = log.find("listening to the store's notifications", at + 1))
      ++n;
    return n;
  };
  EXPECT_TRUE(eventually([&] { return listenings(a.log()) >= 2 && listenings(b.log()) >= 2; }, 10))
      << a.log() << b.log();
  for (auto* c : {ca.get(), cb.get()}) {
    auto metrics = c->Get("/metrics");
    ASSERT_TRUE(metrics);
    EXPECT_NE(metrics->body.find("\ntessera_store_notifications_up 1\n"), std::string::npos) << metrics->body;
  }
  const auto s = stop_through_the_other_node(pg, uri, a, "node-a", b, "cancel");
  ASSERT_TRUE(s);
  EXPECT_LT(*s, 1.0);
}

}  // namespace
}  // namespace tessera::server::test
