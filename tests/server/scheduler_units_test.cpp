// A client's cancel or pause of a split job (work_units.h) made through a node that renders one of its units: the
// job service has the store take the change before the call returns, so the nodes rendering its other units hear of
// it at once (the store's notification), and the unit here then stops (Scheduler::stop) and records nothing. Over the
// throw-away PostgreSQL server (the only store that splits jobs).
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <variant>

#include "renderer/thread_pool.h"
#include "server/files/assets.h"
#include "server/files/events.h"
#include "server/files/job_files.h"
#include "server/jobs/job_service.h"
#include "server/jobs/metrics.h"
#include "server/jobs/scheduler.h"
#include "server/jobs/submission.h"
#include "server/store/postgres_job_store.h"
#include "tests/server/forwarding_store.h"
#include "tests/server/postgres_cluster.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using namespace std::chrono_literals;

// The PostgreSQL store, except that the end of a run waits until the test lets it go: a change that only a run's end
// would record is not in the store while the test looks.
class HeldEndStore final : public test::ForwardingStore {
 public:
  using ForwardingStore::ForwardingStore;

  bool end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms, const std::string& stop_reason,
               const std::string& error) override {
    {
      std::unique_lock lock(mutex_);
      ++ends_;
      cv_.wait(lock, [this] { return released_; });
    }
    return inner_.end_run(id, epoch, to, now_ms, stop_reason, error);
  }
  void release() {
    {
      std::lock_guard lock(mutex_);
      released_ = true;
    }
    cv_.notify_all();
  }
  int ends() {
    std::lock_guard lock(mutex_);
    return ends_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  bool released_ = false;
  int ends_ = 0;
};

class SchedulerUnits : public ::testing::Test {
 protected:
  // A job of two units, each far longer than the test, with one of them rendering here.
  std::string start_split_job() {
    const nlohmann::json doc = test::cornell_job(64, 4096);
    JobRecord job = test::accepted_job_record(doc);
    job.units = 2;
    postgres_.create(job);
    scheduler_.start();
    EXPECT_TRUE(test::eventually(
        [&] {
          for (const UnitRecord& u : postgres_.units(job.id))
            if (u.checkpoint_epoch > 0) return true;  // its first pass is done: the render is under way
          return false;
        },
        120));
    return job.id;
  }

  JobState state_of(const std::string& id) { return postgres_.get(id, false).value().state; }

  // A client's action through the job service.
  bool act(const std::string& id, JobAction action) {
    return std::holds_alternative<ActionTaken>(jobs_.act(postgres_.get(id, false).value(), action));
  }

  void TearDown() override {
    store_.release();
    scheduler_.shutdown();
  }

  test::TempDir dir_;
  PostgresJobStore postgres_{test::PostgresCluster::shared().create_database(), "node-a"};
  HeldEndStore store_{postgres_};
  DirectoryJobFiles files_{dir_.path()};
  ThreadPool pool_{1};
  Scheduler scheduler_{store_, files_, pool_, SchedulerOptions{}};
  DirectoryAssetStore assets_{dir_.path()};
  EventHub events_;
  Metrics metrics_;
  JobService jobs_{store_, files_, assets_, scheduler_, events_, metrics_, JobServiceOptions{}};
};

TEST_F(SchedulerUnits, ACancelThroughTheRenderingNodeIsInTheStoreWhenItReturns) {
  const std::string id = start_split_job();
  EXPECT_TRUE(act(id, JobAction::kCancel));
  EXPECT_EQ(state_of(id), JobState::kCancelled);
  // The unit here stops without recording an end of its own.
  EXPECT_TRUE(test::eventually([&] { return scheduler_.running_count() == 0; }, 60));
  EXPECT_EQ(store_.ends(), 0);
  EXPECT_EQ(state_of(id), JobState::kCancelled);
}

TEST_F(SchedulerUnits, APauseThroughTheRenderingNodeIsInTheStoreWhenItReturns) {
  const std::string id = start_split_job();
  EXPECT_TRUE(act(id, JobAction::kPause));
  EXPECT_EQ(state_of(id), JobState::kPaused);
  EXPECT_TRUE(test::eventually([&] { return scheduler_.running_count() == 0; }, 60));
  EXPECT_EQ(store_.ends(), 0);
  // Its units wait with their checkpoints, and it resumes: back in the queue, where this node's scheduler (free again)
  // may claim it at once, so the state read after the call is queued or already running again.
  for (const UnitRecord& u : postgres_.units(id)) EXPECT_FALSE(u.done);
  EXPECT_TRUE(act(id, JobAction::kResume));
  const JobState after = state_of(id);
  EXPECT_TRUE(after == JobState::kQueued || after == JobState::kRunning) << job_state_name(after);
  EXPECT_TRUE(test::eventually([&] { return scheduler_.running_count() == 1; }, 60));
  EXPECT_EQ(state_of(id), JobState::kRunning);
}

}  // namespace
}  // namespace tessera::server
