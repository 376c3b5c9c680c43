// Retention of finished jobs: which jobs a sweep deletes (only ended ones, older than the retention, each at most
// once), that the store's conditional removal keeps a job requeued meanwhile, and that the sweeper stops at once.
#include <gtest/gtest.h>

#include <chrono>
#include <set>

#include "server/jobs/metrics.h"
#include "server/jobs/retention.h"
#include "server/store/sqlite_job_store.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using test::make_job;

// A job created at 0 that ended `to` at `finished_ms`.
std::string ended_job(JobStore& store, JobState to, int64_t finished_ms) {
  JobRecord j = make_job(0, 0);
  store.create(j);
  if (to != JobState::kCancelled) {
    EXPECT_TRUE(store.transition(j.id, JobState::kRunning, 0));
  }
  EXPECT_TRUE(store.transition(j.id, to, finished_ms, "", to == JobState::kFailed ? "boom" : ""));
  return j.id;
}

RetentionSweeper::RemoveExpired store_remover(JobStore& store) {
  return [&store](const std::string& id, int64_t cutoff_ms) { return store.remove(id, cutoff_ms); };
}

TEST(Retention, PeriodIsAQuarterOfTheRetentionFromOneSecondToAMinute) {
  using std::chrono::milliseconds;
  EXPECT_EQ(RetentionSweeper::period(1), milliseconds(1000));
  EXPECT_EQ(RetentionSweeper::period(2), milliseconds(1000));
  EXPECT_EQ(RetentionSweeper::period(8), milliseconds(2000));
  EXPECT_EQ(RetentionSweeper::period(90), milliseconds(22500));
  EXPECT_EQ(RetentionSweeper::period(30 * 86400), milliseconds(60000));
}

TEST(Retention, SweepDeletesOnlyJobsThatEndedBeforeTheCutoff) {
  test::TempDir dir;
  SqliteJobStore sqlite(dir.path() / "jobs.db");
  JobStore& store = sqlite;  // the interface's default arguments
  Metrics metrics;
  const std::string old_succeeded = ended_job(store, JobState::kSucceeded, 1000);
  const std::string old_failed = ended_job(store, JobState::kFailed, 1000);
  const std::string old_cancelled = ended_job(store, JobState::kCancelled, 4999);
  const std::string recent = ended_job(store, JobState::kSucceeded, 5000);  // exactly the retention: kept
  // Created long before the cutoff, never ended.
  JobRecord queued = make_job(0, 0), paused = make_job(0, 0), running = make_job(0, 0);
  store.create(running);
  ASSERT_EQ(store.claim_next(0)->id, running.id);
  store.create(queued);
  store.create(paused);
  ASSERT_TRUE(store.transition(paused.id, JobState::kPaused, 0));

  RetentionSweeper sweeper(store, metrics, 5, store_remover(store));
  EXPECT_EQ(sweeper.sweep(10000), 3);
  for (const std::string& id : {old_succeeded, old_failed, old_cancelled}) EXPECT_FALSE(store.get(id)) << id;
  for (const std::string& id : {recent, queued.id, paused.id, running.id}) EXPECT_TRUE(store.get(id)) << id;
  EXPECT_NE(metrics.render({}).find("tessera_jobs_expired_total 3\n"), std::string::npos);
  EXPECT_EQ(sweeper.sweep(10000), 0);
  EXPECT_EQ(sweeper.sweep(10001), 1);  // now `recent` is older than 5 s
  EXPECT_FALSE(store.get(recent));
  EXPECT_EQ(sweeper.sweep(1000000000), 0);  // however late, active jobs stay
  EXPECT_EQ(store.count_by_state().at(JobState::kQueued), 1);
  EXPECT_EQ(store.count_by_state().at(JobState::kPaused), 1);
  EXPECT_EQ(store.count_by_state().at(JobState::kRunning), 1);
}

TEST(Retention, SweepPagesThroughManyJobsAndEndsWhenSomeCannotGo) {
  test::TempDir dir;
  SqliteJobStore sqlite(dir.path() / "jobs.db");
  JobStore& store = sqlite;  // the interface's default arguments
  Metrics metrics;
  std::set<std::string> ids;
  for (int i = 0; i < 250; ++i) ids.insert(ended_job(store, JobState::kSucceeded, 100 + i));
  // A remover that keeps every third job (as the scheduler keeps one its render thread still holds): the sweep
  // still ends, having offered each job once.
  std::multiset<std::string> offered;
  int n = 0;
  RetentionSweeper picky(store, metrics, 1, [&](const std::string& id, int64_t cutoff_ms) {
    offered.insert(id);
    return ++n % 3 != 0 && store.remove(id, cutoff_ms);
  });
  EXPECT_EQ(picky.sweep(100000), 250 - 250 / 3);
  EXPECT_EQ(offered.size(), 250u);
  EXPECT_EQ(std::set<std::string>(offered.begin(), offered.end()), ids);
  RetentionSweeper all(store, metrics, 1, store_remover(store));
  EXPECT_EQ(all.sweep(100000), 250 / 3);
  EXPECT_TRUE(store.list(JobFilter{}).empty());
}

TEST(Retention, StopsPromptlyAndDoesNothingWhenDisabled) {
  test::TempDir dir;
  SqliteJobStore sqlite(dir.path() / "jobs.db");
  JobStore& store = sqlite;  // the interface's default arguments
  Metrics metrics;
  const std::string old = ended_job(store, JobState::kSucceeded, 1);
  {
    RetentionSweeper off(store, metrics, 0, store_remover(store));
    off.start();
  }
  EXPECT_TRUE(store.get(old));  // 0: kept forever

  RetentionSweeper sweeper(store, metrics, 30 * 86400, store_remover(store));  // a sweep a minute
  sweeper.start();
  const auto t0 = std::chrono::steady_clock::now();
  sweeper.stop();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(1));
  sweeper.stop();  // again: nothing
}

}  // namespace
}  // namespace tessera::server
