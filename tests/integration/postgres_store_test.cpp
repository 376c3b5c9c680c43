// tesserad with its jobs in PostgreSQL (--store postgresql://...), against a throw-away server: a job goes through
// and survives a restart of the daemon, an unreachable database stops the start with its reason, and the end of a
// render that another node cancelled meanwhile is refused by the store, never written over the cancellation.
#include <signal.h>

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "tests/integration/daemon.h"
#include "tests/server/postgres_cluster.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;

std::string submit(httplib::Client& c, const json& doc) {
  auto res = c.Post("/v1/jobs", doc.dump(), "application/json");
  if (!res || res->status != 202) {
    ADD_FAILURE() << "submission refused: " << (res ? res->body : "no answer");
    return "";
  }
  return json::parse(res->body).value("id", "");
}

std::string state_of(httplib::Client& c, const std::string& id) {
  auto res = c.Get("/v1/jobs/" + id);
  return res && res->status == 200 ? json::parse(res->body).value("state", "") : "";
}

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
// renders it. However the render ends, the store keeps the cancellation.
TEST(PostgresStore, TheEndOfARenderCancelledElsewhereIsRefused) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  TempDir dir;
  Daemon d(dir.path() / "data", {"--store", uri, "--threads", "2", "--log-level", "debug"});
  auto c = d.client();
  const std::string id = submit(*c, cornell_job(96, 512));
  ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "running"; }, 30));
  pg.psql(PostgresCluster::database_of(uri),
          "UPDATE tessera_jobs SET state = 'cancelled', finished_at = 1, stop_reason = 'cancelled', "
          "node = NULL WHERE id = '" +
              id + "'");
  ASSERT_TRUE(
      eventually([&] { return d.log().find("the job store refused the end of a job") != std::string::npos; }, 120))
      << d.log();
  EXPECT_EQ(pg.psql(PostgresCluster::database_of(uri),
                    "SELECT state || ',' || stop_reason FROM tessera_jobs WHERE id = '" + id + "'"),
            "cancelled,cancelled");
  EXPECT_EQ(state_of(*c, id), "cancelled");
}

}  // namespace
}  // namespace tessera::server::test
