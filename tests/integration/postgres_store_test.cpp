// tesserad with its jobs in PostgreSQL (--store postgresql://...), against a throw-away server: a job goes through
// and survives a restart of the daemon, an unreachable database stops the start with its reason, a render cancelled
// through another node stops within seconds and writes nothing over the cancellation, and a node paused past its
// lease is taken over, its late writes refused.
#include <signal.h>

#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <memory>
#include <set>
#include <thread>

#include "renderer/image_io.h"
#include "tests/integration/daemon.h"
#include "tests/integration/postgres_nodes.h"
#include "tests/server/postgres_cluster.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;

TEST(PostgresStore, ADaemonRendersAJobAndFindsItAgainAfterARestart) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  TempDir dir;
  const std::vector<std::string> args = {"--store", uri, "--node", "node-a", "--threads", "2"};
  std::string id;
  {
    Daemon d(dir.path() / "data", args);
    auto c = d.client();
    id = submit(*c, cornell_job(16, 4));
    ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "succeeded"; }, 60)) << d.log();
    auto png = c->Get("/v1/jobs/" + id + "/result.png");
    ASSERT_TRUE(png);
    EXPECT_EQ(png->status, 200);
    // The metrics say which daemon they come from.
    auto metrics = c->Get("/metrics");
    ASSERT_TRUE(metrics);
    EXPECT_NE(metrics->body.find("tessera_node_info{node=\"node-a\",store=\"postgresql\"} 1\n"), std::string::npos)
        << metrics->body;
    EXPECT_EQ(d.stop(SIGTERM), 0);
  }
  // The row is PostgreSQL's: ended, and no longer any node's.
  EXPECT_EQ(pg.psql(PostgresCluster::database_of(uri),
                    "SELECT state || ',' || COALESCE(node, '-') FROM tessera_jobs WHERE id = '" + id + "'"),
            "succeeded,-");
  Daemon again(dir.path() / "data", args);
  auto c = again.client();
  EXPECT_EQ(state_of(*c, id), "succeeded");
}

TEST(PostgresStore, AnUnreachableDatabaseStopsTheStartWithItsReason) {
  TempDir dir;
  try {
    Daemon d(dir.path() / "data", {"--store", PostgresCluster::shared().uri("no_such_database")});
    ADD_FAILURE() << "tesserad started without its database";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot connect to PostgreSQL"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no_such_database"), std::string::npos) << e.what();
  }
}

// Another node (here: an UPDATE made directly, as another daemon's cancel would) cancels a job while this daemon
// renders it: the render loses its lease at its next renewal (every second), stops, and writes nothing over the
// cancellation.
TEST(PostgresStore, ARenderCancelledElsewhereStopsWithinSecondsAndRecordsNothing) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  TempDir dir;
  Daemon d(dir.path() / "data", {"--store", uri, "--threads", "2"});
  auto c = d.client();
  const std::string id = submit(*c, long_cornell_job());
  ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "running"; }, 30));
  pg.psql(PostgresCluster::database_of(uri),
          "UPDATE tessera_jobs SET state = 'cancelled', finished_at = 1, stop_reason = 'cancelled', node = NULL "
          "WHERE id = '" +
              id + "'");
  const auto cancelled_at = std::chrono::steady_clock::now();
  ASSERT_TRUE(eventually([&] { return d.log().find("changed or taken over elsewhere") != std::string::npos; }, 30))
      << d.log();
  EXPECT_LT(std::chrono::steady_clock::now() - cancelled_at, std::chrono::seconds(5));
  // The render's thread is gone: the daemon renders nothing (the metrics' busy threads fall to zero).
  EXPECT_TRUE(eventually(
      [&] {
        auto m = c->Get("/metrics");
        return m && m->body.find("tessera_render_threads_busy 0") != std::string::npos;
      },
      10));
  EXPECT_EQ(row_of(pg, uri, id, "state || ',' || stop_reason || ',' || finished_at"), "cancelled,cancelled,1");
}

// A node stopped (SIGSTOP) for longer than its lease: another takes the job over under the next epoch and finishes
// it; the first, continued (SIGCONT), finds its lease gone and writes nothing more.
TEST(PostgresStore, ANodePausedPastItsLeaseIsTakenOverAndItsLateWritesAreRefused) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  TempDir dir;
  Daemon a(dir.path() / "a", {"--store", uri, "--node", "node-a", "--lease-s", "2", "--threads", "1"});
  auto ca = a.client();
  const std::string id = submit(*ca, cornell_job(64, 256));
  ASSERT_TRUE(eventually([&] { return row_of(pg, uri, id, "state || ',' || node") == "running,node-a"; }, 30));
  kill(a.pid(), SIGSTOP);
  Daemon b(dir.path() / "b", {"--store", uri, "--node", "node-b", "--lease-s", "2", "--threads", "1"});
  ASSERT_TRUE(eventually([&] { return row_of(pg, uri, id, "node || ',' || epoch") == "node-b,2"; }, 30)) << b.log();
  kill(a.pid(), SIGCONT);
  ASSERT_TRUE(eventually([&] { return a.log().find("changed or taken over elsewhere") != std::string::npos; }, 30))
      << a.log();
  auto cb = b.client();
  ASSERT_TRUE(eventually([&] { return state_of(*cb, id) == "succeeded"; }, 120)) << b.log();
  EXPECT_EQ(row_of(pg, uri, id, "state || ',' || epoch || ',' || samples_done"), "succeeded,2,256");
  EXPECT_EQ(a.log().find("job succeeded"), std::string::npos);
  auto exr = cb->Get("/v1/jobs/" + id + "/result.exr");
  ASSERT_TRUE(exr);
  EXPECT_EQ(exr->status, 200);
}

// Daemons sharing the store share one data directory too (a volume every node mounts), each under its own node
// name: a job submitted to one is served by the other, a node frozen past its lease is taken over and the job resumes
// from its checkpoint on the other node, and the image is the one a single daemon renders.
TEST(PostgresStore, NodesSharingADataDirectoryServeEachOthersJobsAndResumeATakenOverOne) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  TempDir dir;
  const auto shared = dir.path() / "shared";
  auto node = [&](const std::string& name) {
    return std::vector<std::string>{"--store", uri, "--node", name, "--lease-s", "2", "--threads", "1"};
  };
  Daemon a(shared, node("node-a"));
  // One name, one daemon, also on a shared directory.
  try {
    Daemon twin(shared, node("node-a"));
    ADD_FAILURE() << "a second node-a started";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("the node name node-a is in use"), std::string::npos) << e.what();
  }
  auto ca = a.client();
  const nlohmann::json job = cornell_job(64, 512);
  const std::string id = submit(*ca, job);
  ASSERT_TRUE(eventually([&] { return row_of(pg, uri, id, "node || ',' || (passes >= 2)::int") == "node-a,1"; }, 60));
  kill(a.pid(), SIGSTOP);
  Daemon b(shared, node("node-b"));
  auto cb = b.client();
  ASSERT_TRUE(eventually([&] { return state_of(*cb, id) == "succeeded"; }, 120)) << b.log();
  EXPECT_NE(b.log().find("job resumed from its checkpoint"), std::string::npos) << b.log();
  kill(a.pid(), SIGCONT);
  ASSERT_TRUE(eventually([&] { return a.log().find("changed or taken over elsewhere") != std::string::npos; }, 30));
  // Either node serves the result, and it is the image of one uninterrupted render.
  auto from_a = ca->Get("/v1/jobs/" + id + "/result.exr");
  auto from_b = cb->Get("/v1/jobs/" + id + "/result.exr");
  ASSERT_TRUE(from_a && from_b);
  ASSERT_EQ(from_a->status, 200);
  ASSERT_EQ(from_b->status, 200);
  EXPECT_EQ(from_a->body, from_b->body);
  Daemon alone(dir.path() / "alone", {"--threads", "1"});
  auto c1 = alone.client();
  const std::string reference = submit(*c1, job);
  ASSERT_TRUE(eventually([&] { return state_of(*c1, reference) == "succeeded"; }, 120));
  auto one = c1->Get("/v1/jobs/" + reference + "/result.exr");
  ASSERT_TRUE(one);
  auto pixels = [&](const std::string& bytes, const std::string& name) {
    const auto file = dir.path() / name;
    std::ofstream(file, std::ios::binary) << bytes;
    return read_image(file.string()).pixels;
  };
  EXPECT_TRUE(pixels(from_b->body, "cluster.exr") == pixels(one->body, "alone.exr"))
      << "the image rendered across two nodes differs from the one-node render";
}

// --max-running-per-user across nodes: two nodes of two render slots each, alice's three long jobs and then bob's
// one. Without the cap alice would hold three of the four slots; with a cap of 1 she holds one, whichever node runs
// it, bob's job runs beside it, and her other two wait in the queue, for as long as the test watches (3 s, three
// claim polls of each node).
TEST(PostgresStore, TwoNodesGiveEachUserNoMoreRunsThanTheCap) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  TempDir dir;
  const std::string alice = "alice-token-0123456789", bob = "bob-token-0123456789";
  const auto tokens = dir.path() / "tokens.json";
  std::ofstream(tokens) << json::array(
      {{{"token", alice}, {"name", "alice"}, {"role", "user"}}, {{"token", bob}, {"name", "bob"}, {"role", "user"}}});
  auto node = [&](const std::string& name) {
    return std::vector<std::string>{"--store",
                                    uri,
                                    "--node",
                                    name,
                                    "--threads",
                                    "1",
                                    "--max-jobs",
                                    "2",
                                    "--tokens",
                                    tokens.string(),
                                    "--max-running-per-user",
                                    "1"};
  };
  Daemon a(dir.path() / "shared", node("node-a"));
  Daemon b(dir.path() / "shared", node("node-b"));
  auto ca = a.client(), cb = b.client();
  ca->set_default_headers({{"Authorization", "Bearer " + alice}});
  cb->set_default_headers({{"Authorization", "Bearer " + bob}});
  // Long, and rendered whole (a job with a time limit is one unit).
  json job = cornell_job(64, 65536);
  job["render"]["time_limit_s"] = 600;
  std::vector<std::string> alices;
  for (int i = 0; i < 3; ++i) alices.push_back(submit(*ca, job));
  const std::string bobs = submit(*cb, job);
  // Running jobs per owner, as "owner:count,..." in owner order.
  auto running = [&] {
    return pg.psql(PostgresCluster::database_of(uri),
                   "SELECT string_agg(owner || ':' || n, ',' ORDER BY owner) FROM (SELECT owner, count(*) AS n FROM "
                   "tessera_jobs WHERE state = 'running' GROUP BY owner) c");
  };
  ASSERT_TRUE(eventually([&] { return state_of(*cb, bobs) == "running"; }, 60)) << a.log() << b.log();
  std::string seen;
  for (int i = 0; i < 30; ++i) {
    seen = running();
    ASSERT_EQ(seen, "alice:1,bob:1");
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  int queued = 0;
  for (const std::string& id : alices) queued += state_of(*ca, id) == "queued";
  EXPECT_EQ(queued, 2);
  // Cancelling alice's running job lets her next one run, on either node: the store has the cancel when the answer
  // comes, whichever node renders the job, and her next job may be claimed at once (so it is not looked for before).
  std::string cancelled;
  for (const std::string& id : alices)
    if (state_of(*ca, id) == "running") cancelled = id;
  ASSERT_FALSE(cancelled.empty());
  const int status = ca->Post("/v1/jobs/" + cancelled + "/cancel")->status;
  ASSERT_EQ(status, 200);
  ASSERT_TRUE(eventually(
      [&] {
        int n = 0;
        for (const std::string& id : alices) n += state_of(*ca, id) == "running";
        return n == 1 && running() == "alice:1,bob:1";
      },
      30));
}

// Three nodes on one store and one volume, 200 jobs of five priorities submitted to them at once, one node killed
// (SIGKILL) on the way: every job ends succeeded, none is lost, none is claimed twice except those the killed node
// held (taken over once its lease ran out), each node took its share, and the claims of all three kept the priority
// order: no job was claimed while one of a higher priority had been waiting for it, unless that one was being claimed
// at the same moment by another node (SKIP LOCKED passes over it).
TEST(PostgresStore, ThreeNodesRunTwoHundredJobsAndLoseNoneWhenOneIsKilled) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  TempDir dir;
  const auto shared = dir.path() / "shared";
  auto node = [&](const std::string& name) {
    return std::vector<std::string>{"--store", uri, "--node", name, "--lease-s", "2", "--threads", "1"};
  };
  Daemon n1(shared, node("n1")), n2(shared, node("n2"));
  auto n3 = std::make_unique<Daemon>(shared, node("n3"));
  // The database notes, with its own clock and sequence, when each job was queued and claimed.
  pg.psql(PostgresCluster::database_of(uri), R"sql(
    CREATE TABLE test_queued (id TEXT, priority INT, at TIMESTAMPTZ DEFAULT clock_timestamp());
    CREATE TABLE test_claims (n BIGSERIAL, id TEXT, priority INT, at TIMESTAMPTZ DEFAULT clock_timestamp());
    CREATE FUNCTION test_note() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN
      IF TG_OP = 'INSERT' THEN INSERT INTO test_queued (id, priority) VALUES (NEW.id, NEW.priority);
      ELSIF NEW.state = 'running' AND OLD.state <> 'running' THEN
        INSERT INTO test_claims (id, priority) VALUES (NEW.id, NEW.priority);
      END IF;
      RETURN NEW;
    END $$;
    CREATE TRIGGER test_note AFTER INSERT OR UPDATE ON tessera_jobs FOR EACH ROW EXECUTE FUNCTION test_note();
  )sql");
  std::vector<std::unique_ptr<httplib::Client>> clients;
  clients.push_back(n1.client());
  clients.push_back(n2.client());
  constexpr int kJobs = 200;
  std::vector<std::string> ids(kJobs);
  std::vector<std::thread> submitters;
  for (int t = 0; t < 3; ++t) {
    submitters.emplace_back([&, t] {
      auto c = t == 0 ? n1.client() : t == 1 ? n2.client() : n3->client();  // a connection of its own each
      for (int i = t; i < kJobs; i += 3) {
        json doc = cornell_job(16, 16);
        doc["priority"] = (i * 7) % 5;
        ids[i] = submit(*c, doc);
      }
    });
  }
  for (auto& t : submitters) t.join();
  // n3 dies once it has rendered some.
  ASSERT_TRUE(eventually(
      [&] {
        return std::stoi(pg.psql(PostgresCluster::database_of(uri),
                                 "SELECT COUNT(*) FROM tessera_jobs WHERE state = 'succeeded'")) >= 30;
      },
      120));
  n3->stop(SIGKILL);
  ASSERT_TRUE(eventually(
      [&] {
        return pg.psql(PostgresCluster::database_of(uri),
                       "SELECT COUNT(*) FROM tessera_jobs WHERE state = 'succeeded'") == std::to_string(kJobs);
      },
      240))
      << pg.psql(PostgresCluster::database_of(uri), "SELECT state, COUNT(*) FROM tessera_jobs GROUP BY state");
  EXPECT_EQ(std::set<std::string>(ids.begin(), ids.end()).size(), static_cast<size_t>(kJobs));  // all accepted
  // Claimed more than once: only jobs n3 held when it died (one at a time: --max-jobs 1).
  EXPECT_LE(std::stoi(pg.psql(PostgresCluster::database_of(uri), "SELECT COUNT(*) FROM tessera_jobs WHERE epoch > 1")),
            1);
  // Priority order across nodes: pairs (a, b) where b was claimed while a, of a higher priority, had been queued for
  // 100 ms (committed, then), yet a was claimed later, and not among the two claims next to b's (the other nodes'
  // claims under way at that moment).
  const std::string inversions = pg.psql(PostgresCluster::database_of(uri), R"sql(
    SELECT COUNT(*) FROM test_claims b JOIN test_queued qa ON qa.priority > b.priority
      AND qa.at < b.at - interval '100 milliseconds'
      JOIN test_claims a ON a.id = qa.id AND a.n > b.n + 2
  )sql");
  EXPECT_EQ(inversions, "0") << pg.psql(PostgresCluster::database_of(uri),
                                        "SELECT n, priority, at FROM test_claims ORDER BY n");
  // And the order mattered: jobs of different priorities were waiting together.
  EXPECT_NE(pg.psql(PostgresCluster::database_of(uri), R"sql(
    SELECT COUNT(*) FROM test_claims a JOIN test_claims b ON a.priority > b.priority
      JOIN test_queued qa ON qa.id = a.id JOIN test_queued qb ON qb.id = b.id
      WHERE GREATEST(qa.at, qb.at) < LEAST(a.at, b.at) - interval '100 milliseconds'
  )sql"),
            "0");
  // Both survivors rendered some, and either answers for any job.
  EXPECT_NE(n1.log().find("job succeeded"), std::string::npos);
  EXPECT_NE(n2.log().find("job succeeded"), std::string::npos);
  EXPECT_EQ(state_of(*clients[0], ids[kJobs - 1]), "succeeded");
  EXPECT_EQ(state_of(*clients[1], ids[kJobs - 2]), "succeeded");
}

}  // namespace
}  // namespace tessera::server::test
