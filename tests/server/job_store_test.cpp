// The SQLite job store: claim order, the state machine, persistence across reopening (a daemon restart).
#include <gtest/gtest.h>
#include <sqlite3.h>

#include "server/job_id.h"
#include "server/sqlite_job_store.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using test::make_job;

TEST(SqliteJobStore, ClaimsByPriorityThenFirstCome) {
  test::TempDir dir;
  SqliteJobStore store(dir.path() / "jobs.db");
  JobRecord a = make_job(0, 1), b = make_job(5, 2), c = make_job(0, 3), d = make_job(5, 4);
  for (const JobRecord* j : {&a, &b, &c, &d}) store.create(*j);
  std::vector<std::string> order;
  while (auto j = store.claim_next(100)) {
    EXPECT_EQ(j->state, JobState::kRunning);
    EXPECT_EQ(j->started_at_ms, 100);
    EXPECT_EQ(j->document, R"({"kind":"scene"})");  // a claim brings the document to render
    order.push_back(j->id);
  }
  EXPECT_EQ(order, (std::vector<std::string>{b.id, d.id, a.id, c.id}));
}

TEST(SqliteJobStore, TransitionsFollowTheStateMachine) {
  test::TempDir dir;
  SqliteJobStore store(dir.path() / "jobs.db");
  JobRecord a = make_job(0, 1);
  store.create(a);
  EXPECT_FALSE(store.transition(a.id, JobState::kSucceeded, 5, "samples", ""));  // queued cannot succeed
  ASSERT_TRUE(store.claim_next(2));
  JobProgress p;
  p.passes = 3;
  p.samples_done = 7;
  p.samples_total = 16;
  p.elapsed_s = 1.5;
  p.eta_s = 2;
  p.samples_per_s = 1000;
  store.update_progress(a.id, p);
  EXPECT_TRUE(store.transition(a.id, JobState::kSucceeded, 9, "samples", ""));
  EXPECT_FALSE(store.transition(a.id, JobState::kCancelled, 10, "cancelled", ""));  // terminal stays terminal
  auto got = store.get(a.id, false);
  ASSERT_TRUE(got);
  EXPECT_EQ(got->state, JobState::kSucceeded);
  EXPECT_EQ(got->finished_at_ms, 9);
  EXPECT_EQ(got->stop_reason, "samples");
  EXPECT_EQ(got->progress.passes, 3u);
  EXPECT_EQ(got->progress.samples_done, 7u);
  EXPECT_TRUE(got->document.empty());                                             // not asked for
  EXPECT_FALSE(store.transition(new_job_id(), JobState::kCancelled, 1, "", ""));  // unknown id
}

TEST(SqliteJobStore, FailedJobKeepsItsError) {
  test::TempDir dir;
  SqliteJobStore store(dir.path() / "jobs.db");
  JobRecord a = make_job(0, 1);
  store.create(a);
  store.claim_next(2);
  EXPECT_TRUE(store.transition(a.id, JobState::kFailed, 3, "", "out of memory"));
  EXPECT_EQ(store.get(a.id, false)->error, "out of memory");
}

TEST(SqliteJobStore, KeepsTheJobsNameAndGivesOlderJobsAnEmptyOne) {
  test::TempDir dir;
  const auto file = dir.path() / "jobs.db";
  JobRecord old_job = make_job(0, 1), named = make_job(0, 2);
  named.name = "Cornell box, 4096 spp";
  {
    SqliteJobStore store(file);
    store.create(old_job);
  }
  // The file as a daemon of schema version 2 left it: no name column.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(file.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "ALTER TABLE jobs DROP COLUMN name; DELETE FROM schema_version WHERE version = 3", nullptr,
                         nullptr, nullptr),
            SQLITE_OK)
      << sqlite3_errmsg(db);
  sqlite3_close(db);
  SqliteJobStore store(file);
  store.create(named);
  EXPECT_EQ(store.get(old_job.id, false).value().name, "");
  EXPECT_EQ(store.get(named.id, false).value().name, "Cornell box, 4096 spp");
  EXPECT_EQ(store.claim_next(3).value().name, "");
  EXPECT_EQ(store.list(JobFilter{}).front().name, "Cornell box, 4096 spp");
}

TEST(SqliteJobStore, RestartRequeuesRunningJobsAndKeepsTheRest) {
  test::TempDir dir;
  JobRecord done = make_job(0, 1), running = make_job(0, 2), queued = make_job(0, 3);
  {
    SqliteJobStore store(dir.path() / "jobs.db");
    store.create(done);
    store.create(running);
    store.create(queued);
    ASSERT_EQ(store.claim_next(5)->id, done.id);
    ASSERT_TRUE(store.transition(done.id, JobState::kSucceeded, 6, "samples", ""));
    ASSERT_EQ(store.claim_next(7)->id, running.id);
    JobProgress p;
    p.passes = 2;
    p.samples_done = 3;
    store.update_progress(running.id, p);
  }  // the process "dies" with one job running
  SqliteJobStore store(dir.path() / "jobs.db");
  EXPECT_EQ(store.requeue_running(), 1);
  auto r = store.get(running.id, false);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->state, JobState::kQueued);
  EXPECT_EQ(r->progress.samples_done, 0u);  // the render starts over
  EXPECT_FALSE(r->started_at_ms);
  EXPECT_EQ(store.get(done.id, false)->state, JobState::kSucceeded);
  // The requeued job keeps its place: submitted before `queued`, it is claimed first.
  EXPECT_EQ(store.claim_next(8)->id, running.id);
  EXPECT_EQ(store.claim_next(8)->id, queued.id);
}

TEST(SqliteJobStore, ListsNewestFirstWithFilterAndLimit) {
  test::TempDir dir;
  SqliteJobStore store(dir.path() / "jobs.db");
  std::vector<JobRecord> jobs;
  for (int i = 0; i < 5; ++i) {
    jobs.push_back(make_job(i % 2, i));
    store.create(jobs.back());
  }
  store.claim_next(10);  // jobs[1] (priority 1, first)
  auto all = store.list({});
  ASSERT_EQ(all.size(), 5u);
  EXPECT_EQ(all.front().id, jobs[4].id);
  EXPECT_EQ(all.back().id, jobs[0].id);
  JobFilter running;
  running.state = JobState::kRunning;
  auto r = store.list(running);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].id, jobs[1].id);
  JobFilter two;
  two.limit = 2;
  EXPECT_EQ(store.list(two).size(), 2u);
}

TEST(SqliteJobStore, RemoveAndDuplicateIds) {
  test::TempDir dir;
  SqliteJobStore store(dir.path() / "jobs.db");
  JobRecord a = make_job(0, 1);
  store.create(a);
  try {
    store.create(a);
    ADD_FAILURE() << "a duplicate id was stored";
  } catch (const JobStoreError& e) {
    EXPECT_FALSE(e.out_of_space()) << e.what();  // refused, not for want of room
  }
  EXPECT_TRUE(store.remove(a.id));
  EXPECT_FALSE(store.remove(a.id));
  EXPECT_FALSE(store.get(a.id, false));
}

TEST(SqliteJobStore, RefusesANewerSchema) {
  test::TempDir dir;
  const auto file = dir.path() / "jobs.db";
  { SqliteJobStore store(file); }
  // A later daemon migrated the file; this one must not write to it.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(file.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "INSERT INTO schema_version (version) VALUES (99)", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  EXPECT_THROW(SqliteJobStore{file}, JobStoreError);
}

// The file-size limit (EFBIG, or a short write) stands in for a full disk (ENOSPC): SQLite says SQLITE_FULL or an I/O
// error, and either way the store says it ran out of room, so that POST /v1/jobs can answer 507.
TEST(SqliteJobStore, AFullDiskIsAnOutOfSpaceErrorAndStoresNothing) {
  test::TempDir dir;
  SqliteJobStore store(dir.path() / "jobs.db");
  JobRecord big = make_job(0, 1);
  big.document = nlohmann::json{{"kind", "scene"}, {"padding", std::string(1 << 20, 'x')}}.dump();
  {
    test::FileSizeLimit limit(256 << 10);
    try {
      store.create(big);
      ADD_FAILURE() << "a 1 MiB job was stored under a 256 KiB file-size limit";
    } catch (const JobStoreError& e) {
      EXPECT_TRUE(e.out_of_space()) << e.what();
    }
  }
  EXPECT_FALSE(store.get(big.id, false));  // the insert was rolled back whole
  // With room again the store goes on.
  store.create(big);
  EXPECT_EQ(store.get(big.id, true)->document, big.document);
  EXPECT_EQ(store.count_by_state(std::nullopt).at(JobState::kQueued), 1);
}

}  // namespace
}  // namespace tessera::server
