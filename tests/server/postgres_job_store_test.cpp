// What only the PostgreSQL store does (the rest is job_store_conformance_test.cpp): versioned migrations run once
// however many daemons start together, a newer schema refused, a restart that puts back only its own node's jobs, a
// connection that comes back after the server restarted. And the test server itself: without PostgreSQL's programs a
// test fails, saying what to install.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <atomic>
#include <thread>

#include "server/postgres_job_store.h"
#include "tests/server/postgres_cluster.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using test::make_job;
using test::PostgresCluster;

TEST(PostgresJobStore, DaemonsStartingTogetherMigrateOnce) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  std::atomic<int> failures{0};
  std::vector<std::thread> daemons;
  for (int i = 0; i < 4; ++i) {
    daemons.emplace_back([&, i] {
      try {
        PostgresJobStore store(uri, "node-" + std::to_string(i));
      } catch (const std::exception& e) {
        ADD_FAILURE() << e.what();
        ++failures;
      }
    });
  }
  for (auto& t : daemons) t.join();
  EXPECT_EQ(failures.load(), 0);
  std::string versions;  // each migration once, in order: "1,2,..."
  for (int v = 1; v <= PostgresJobStore::schema_version(); ++v) {
    if (v > 1) versions += ",";
    versions += std::to_string(v);
  }
  EXPECT_EQ(pg.psql(PostgresCluster::database_of(uri),
                    "SELECT string_agg(version::text, ',' ORDER BY version) FROM tessera_schema_version"),
            versions);
  // Started again: nothing to do, nothing recorded twice.
  PostgresJobStore again(uri, "node-0");
  EXPECT_EQ(pg.psql(PostgresCluster::database_of(uri), "SELECT COUNT(*) FROM tessera_schema_version"),
            std::to_string(PostgresJobStore::schema_version()));
}

TEST(PostgresJobStore, RefusesANewerSchema) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  { PostgresJobStore store(uri, "a"); }
  // A later daemon migrated the database; this one must not write to it.
  pg.psql(PostgresCluster::database_of(uri), "INSERT INTO tessera_schema_version (version) VALUES (99)");
  try {
    PostgresJobStore store(uri, "a");
    ADD_FAILURE() << "a database of schema version 99 was used";
  } catch (const JobStoreError& e) {
    EXPECT_NE(std::string(e.what()).find("schema version 99"), std::string::npos) << e.what();
  }
}

TEST(PostgresJobStore, AnUnreachableDatabaseIsAStoreError) {
  PostgresCluster& pg = PostgresCluster::shared();
  EXPECT_THROW(PostgresJobStore(pg.uri("no_such_database"), "a"), JobStoreError);
}

// Daemons share the database: one that restarts puts back the jobs it was rendering, never another node's.
TEST(PostgresJobStore, ARestartRequeuesOnlyItsOwnNodesJobs) {
  const std::string uri = PostgresCluster::shared().create_database();
  PostgresJobStore a(uri, "node-a"), b(uri, "node-b");
  JobRecord mine = make_job(0, 1), theirs = make_job(0, 2);
  a.create(mine);
  a.create(theirs);
  ASSERT_EQ(a.claim_next(3)->id, mine.id);
  ASSERT_EQ(b.claim_next(3)->id, theirs.id);
  PostgresJobStore a_again(uri, "node-a");
  EXPECT_EQ(a_again.requeue_running(), 1);
  EXPECT_EQ(a_again.get(mine.id, false)->state, JobState::kQueued);
  EXPECT_EQ(a_again.get(theirs.id, false)->state, JobState::kRunning);
}

// The server restarted (an upgrade, a failover): the call that finds the connection broken fails as the store
// failing, and the next one connects again; nothing committed is lost.
TEST(PostgresJobStore, ReconnectsAfterTheServerRestarted) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  PostgresJobStore store(uri, "a");
  JobRecord j = make_job(0, 1);
  store.create(j);
  pg.restart();
  std::optional<JobRecord> got;
  for (int attempt = 0; attempt < 2 && !got; ++attempt) {
    try {
      got = store.get(j.id, false);
    } catch (const JobStoreError&) {
      // the connection found broken
    }
  }
  ASSERT_TRUE(got);
  EXPECT_EQ(got->state, JobState::kQueued);
  EXPECT_EQ(store.claim_next(5)->id, j.id);
}

TEST(PostgresCluster, WithoutTheServerProgramsATestFailsNamingThePackage) {
  const char* saved = getenv("TESSERA_PG_BINDIR");
  const std::string restore = saved ? saved : "";
  setenv("TESSERA_PG_BINDIR", "/nonexistent", 1);
  try {
    PostgresCluster cluster;
    ADD_FAILURE() << "a cluster started without initdb";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("postgresql package"), std::string::npos) << e.what();
  }
  saved ? setenv("TESSERA_PG_BINDIR", restore.c_str(), 1) : unsetenv("TESSERA_PG_BINDIR");
}

}  // namespace
}  // namespace tessera::server
