// What only the PostgreSQL store does (the rest is job_store_conformance_test.cpp): versioned migrations run once
// however many daemons start together, a newer schema refused, a restart that puts back only its own node's jobs, a
// connection that comes back after the server restarted. And the test server itself: without PostgreSQL's programs a
// test fails, saying what to install.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "server/store/postgres_connection.h"
#include "server/store/postgres_job_store.h"
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

// A split job's units (work_units.h): claimed one by one across nodes, each run under its own epoch from the job's
// counter; a stale epoch's renewal, progress and end are refused; a unit whose lease ran out is re-leased under the
// next epoch with its checkpoint; the merge is claimable only once every range is done, and its end is the job's.
TEST(PostgresJobStore, UnitsAreLeasedFencedAndMergedOnce) {
  const std::string uri = PostgresCluster::shared().create_database();
  PostgresJobStore a(uri, "node-a"), b(uri, "node-b");
  JobRecord job = make_job(0, 1);
  job.units = 2;  // samples 0..8 and 8..16
  a.create(job);
  auto u0 = a.claim_next(10, 1000);
  auto u1 = b.claim_next(10, 1000);
  ASSERT_TRUE(u0 && u1);
  EXPECT_EQ(u0->unit, 0);
  EXPECT_EQ(u1->unit, 1);
  EXPECT_EQ(u0->units, 2);
  EXPECT_EQ(u1->unit_first_sample, 8u);
  EXPECT_EQ(u1->unit_samples, 8u);
  EXPECT_NE(u0->epoch, u1->epoch);
  EXPECT_EQ(a.get(job.id, false)->state, JobState::kRunning);
  EXPECT_FALSE(a.claim_next(20, 1000)) << "the merge was claimable before its units were done";
  // Progress of unit 0 records its checkpoint; the job's progress sums its units.
  JobProgress p;
  p.passes = 1;
  p.samples_done = 4;
  p.elapsed_s = 1;
  EXPECT_TRUE(a.update_progress(job.id, u0->epoch, p));
  EXPECT_EQ(a.get(job.id, false)->progress.samples_done, 4u);
  // Node a stops renewing: past the lease, b takes unit 0 over under a newer epoch, with a's checkpoint.
  auto again = b.claim_next(2000, 1000);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->unit, 0);
  EXPECT_GT(again->epoch, u1->epoch);
  EXPECT_EQ(again->unit_checkpoint_epoch, u0->epoch);
  // a's stale run: every write refused.
  EXPECT_FALSE(a.renew_lease(job.id, u0->epoch, 2001, 1000));
  EXPECT_FALSE(a.update_progress(job.id, u0->epoch, p));
  EXPECT_FALSE(a.end_run(job.id, u0->epoch, JobState::kSucceeded, 2001));
  EXPECT_TRUE(b.end_run(job.id, u1->epoch, JobState::kSucceeded, 2002));
  EXPECT_FALSE(a.claim_next(2003, 1000)) << "the merge was claimable before its units were done";
  EXPECT_TRUE(b.end_run(job.id, again->epoch, JobState::kSucceeded, 2004));
  const auto units = a.units(job.id);
  ASSERT_EQ(units.size(), 2u);
  EXPECT_TRUE(units[0].done && units[1].done);
  EXPECT_EQ(units[0].checkpoint_epoch, again->epoch);
  EXPECT_EQ(a.get(job.id, false)->state, JobState::kRunning);
  auto merge = a.claim_next(2005, 1000);
  ASSERT_TRUE(merge);
  EXPECT_EQ(merge->unit, 2);
  EXPECT_FALSE(b.claim_next(2006, 1000));
  EXPECT_TRUE(a.end_run(job.id, merge->epoch, JobState::kSucceeded, 2007, "samples"));
  EXPECT_EQ(a.get(job.id, false)->state, JobState::kSucceeded);
  EXPECT_FALSE(b.claim_next(5000, 1000));
}

// A unit whose node died is a lost run of its job: taken over past its lease, or put back by its node's restart,
// each counts once, however many of the job's units that node held.
TEST(PostgresJobStore, ALostUnitIsALostRunOfItsJob) {
  const std::string uri = PostgresCluster::shared().create_database();
  PostgresJobStore a(uri, "node-a"), b(uri, "node-b");
  JobRecord job = make_job(0, 1);
  job.units = 3;
  a.create(job);
  ASSERT_TRUE(a.claim_next(10, 1000) && a.claim_next(10, 1000));  // units 0 and 1 on node a
  ASSERT_EQ(b.claim_next(10, 1000)->lost_runs, 0);                // unit 2 on node b
  PostgresJobStore a_again(uri, "node-a");
  EXPECT_EQ(a_again.requeue_running(), 2);
  EXPECT_EQ(a.get(job.id, false)->lost_runs, 1);
  // Node b dies too: its unit is taken over past its lease.
  auto taken = a_again.claim_next(3000, 1000);
  ASSERT_TRUE(taken);
  EXPECT_EQ(a.get(job.id, false)->lost_runs, 1) << "a requeued unit claimed again is no new loss";
  while (auto next = a_again.claim_next(3000, 1000)) {
  }
  EXPECT_EQ(a.get(job.id, false)->lost_runs, 2);
}

// A whole job of a higher priority goes before the units of a split one; a split job of a higher priority before a
// whole one; a paused split job's running units wait, unclaimable, until it is resumed.
TEST(PostgresJobStore, UnitsAndWholeJobsAreClaimedByPriorityThenAge) {
  const std::string uri = PostgresCluster::shared().create_database();
  PostgresJobStore a(uri, "node-a");
  JobRecord split = make_job(0, 1), urgent = make_job(5, 2), later = make_job(0, 3);
  split.units = 2;
  a.create(split);
  a.create(urgent);
  a.create(later);
  EXPECT_EQ(a.claim_next(10, 1000)->id, urgent.id);
  auto u0 = a.claim_next(10, 1000);
  ASSERT_TRUE(u0);
  EXPECT_EQ(u0->id, split.id);
  EXPECT_TRUE(a.transition(split.id, JobState::kPaused, 11, "", ""));
  EXPECT_FALSE(a.renew_lease(split.id, u0->epoch, 12, 1000));
  EXPECT_EQ(a.claim_next(13, 1000)->id, later.id);
  EXPECT_FALSE(a.claim_next(14, 1000));
  EXPECT_TRUE(a.transition(split.id, JobState::kQueued, 15, "", "", JobState::kPaused));
  auto resumed = a.claim_next(16, 1000);
  ASSERT_TRUE(resumed);
  EXPECT_EQ(resumed->unit, 0);
  EXPECT_GT(resumed->epoch, u0->epoch);
}

// A split job requeued after its end starts over: its units are queued again and forget their checkpoints; a pause
// and a resume keep them.
TEST(PostgresJobStore, ARequeuedSplitJobStartsItsUnitsOver) {
  const std::string uri = PostgresCluster::shared().create_database();
  PostgresJobStore a(uri, "node-a");
  JobRecord job = make_job(0, 1);
  job.units = 2;
  a.create(job);
  auto u0 = a.claim_next(10, 1000);
  ASSERT_TRUE(u0);
  JobProgress p;
  p.samples_done = 4;
  ASSERT_TRUE(a.update_progress(job.id, u0->epoch, p));
  ASSERT_TRUE(a.transition(job.id, JobState::kPaused, 11, "", ""));
  ASSERT_TRUE(a.transition(job.id, JobState::kQueued, 12, "", "", JobState::kPaused));
  auto resumed = a.claim_next(13, 1000);
  ASSERT_TRUE(resumed);
  EXPECT_EQ(resumed->unit, 0);
  EXPECT_EQ(resumed->unit_checkpoint_epoch, u0->epoch);  // resumed from its checkpoint
  ASSERT_TRUE(a.transition(job.id, JobState::kCancelled, 14, "cancelled", ""));
  ASSERT_TRUE(a.transition(job.id, JobState::kQueued, 15, "", "", JobState::kCancelled));
  for (const UnitRecord& u : a.units(job.id)) {
    EXPECT_FALSE(u.done);
    EXPECT_EQ(u.checkpoint_epoch, 0);
  }
  auto again = a.claim_next(16, 1000);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->unit, 0);
  EXPECT_EQ(again->unit_checkpoint_epoch, 0);  // from its first sample
}

// A unit's lease records when its node last renewed it, beside when it runs out: the status tells from them that a
// node stopped renewing before its lease is up.
TEST(PostgresJobStore, AUnitsLeaseRecordsItsLastRenewal) {
  const std::string uri = PostgresCluster::shared().create_database();
  PostgresJobStore a(uri, "node-a");
  JobRecord job = make_job(0, 1);
  job.units = 2;
  a.create(job);
  auto u0 = a.claim_next(100, 1000);
  ASSERT_TRUE(u0);
  auto running = [&] {
    for (const UnitRecord& u : a.units(job.id))
      if (u.running) return u;
    return UnitRecord{};
  };
  EXPECT_EQ(running().renewed_at_ms, 100);
  EXPECT_EQ(running().lease_expires_at_ms, 1100);
  ASSERT_TRUE(a.renew_lease(job.id, u0->epoch, 700, 1000));
  EXPECT_EQ(running().node, "node-a");
  EXPECT_EQ(running().renewed_at_ms, 700);
  EXPECT_EQ(running().lease_expires_at_ms, 1700);
  // A unit not running shows no lease.
  for (const UnitRecord& u : a.units(job.id)) {
    if (!u.running) {
      EXPECT_EQ(u.renewed_at_ms, 0);
    }
  }
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

// A node stopped between BEGIN and COMMIT (SIGSTOP, a paused VM) holding a job's row: past its idle-transaction limit
// (the daemon's lease) the server ends its session and the row is the other nodes' to write; the stopped node, run
// again, finds its transaction gone and its next statement connects afresh.
TEST(PostgresJobStore, ATransactionLeftOpenHoldsItsRowsNoLongerThanItsLimit) {
  PostgresCluster& pg = PostgresCluster::shared();
  const std::string uri = pg.create_database();
  PostgresJobStore store(uri, "a");
  JobRecord j = make_job(0, 1);
  store.create(j);
  PgConnection stopped(uri, "stopped node", 300);
  stopped.exec("BEGIN");
  stopped.exec("SELECT 1 FROM tessera_jobs WHERE id = $1 FOR UPDATE", {j.id});
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));  // the node does nothing: stopped
  PgConnection other(uri, "another node");
  other.exec("SET lock_timeout = 3000");  // without the limit: blocked behind the row lock, then this error
  EXPECT_NO_THROW(other.exec("UPDATE tessera_jobs SET priority = 7 WHERE id = $1", {j.id}));
  EXPECT_THROW(stopped.exec("COMMIT"), JobStoreError);  // its transaction was rolled back with its session
  EXPECT_EQ(stopped.exec("SELECT priority FROM tessera_jobs WHERE id = $1", {j.id}).int64(0), 7);
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
