// The job service over the real SQLite store and scheduler. In every state, the actions a job's status offers (which
// the web client's buttons show) are exactly the ones the service and the store accept, and a refusal gives the state
// table's reason. A job's end is counted by the metrics in the same step that makes it visible: a scrape that follows
// a read of the ended state never misses it.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <fstream>
#include <thread>
#include <variant>

#include <nlohmann/json.hpp>

#include "renderer/thread_pool.h"
#include "server/files/assets.h"
#include "server/files/events.h"
#include "server/files/job_files.h"
#include "server/jobs/job_service.h"
#include "server/jobs/metrics.h"
#include "server/jobs/scheduler.h"
#include "server/jobs/submission.h"
#include "server/store/sqlite_job_store.h"
#include "tests/server/forwarding_store.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using nlohmann::json;
using namespace std::chrono_literals;

bool offers(const json& status, const std::string& name) {
  const json& actions = status.at("actions");
  return std::find(actions.begin(), actions.end(), name) != actions.end();
}

TEST(JobStateTable, RefusalsSayWhatTheStateAllows) {
  EXPECT_EQ(action_refusal(JobAction::kPause, JobState::kSucceeded),
            "cannot pause a job that is succeeded; only a job that is queued or running can be paused");
  EXPECT_EQ(action_refusal(JobAction::kCancel, JobState::kFailed),
            "cannot cancel a job that is failed; only a job that is queued, running or paused can be cancelled");
  EXPECT_EQ(action_refusal(JobAction::kPriority, JobState::kCancelled),
            "cannot change the priority of a job that is cancelled; only a job that is queued, running or paused can "
            "have its priority changed");
  for (JobState s : kAllJobStates) {
    EXPECT_TRUE(action_allowed(JobAction::kDelete, s));
    // A state change an action makes is one the state machine has.
    for (JobAction a : allowed_actions(s)) {
      if (auto to = action_target(a)) {
        EXPECT_TRUE(can_transition(s, *to)) << job_action_name(a);
      }
    }
  }
}

// A job that failed on its input would fail the same way again: it may be deleted, never requeued; a job that failed
// otherwise may be requeued.
TEST(JobStateTable, AJobThatFailedOnItsInputIsNotRequeued) {
  EXPECT_TRUE(action_allowed(JobAction::kRequeue, JobState::kFailed));
  EXPECT_FALSE(action_allowed(JobAction::kRequeue, JobState::kFailed, true));
  EXPECT_EQ(allowed_actions(JobState::kFailed, true), std::vector<JobAction>{JobAction::kDelete});
  EXPECT_EQ(action_refusal(JobAction::kRequeue, JobState::kFailed, true),
            "cannot requeue a job that failed on its input: the same document fails the same way; submit a corrected "
            "one");
  // Only a failed job has failed on its input.
  EXPECT_TRUE(action_allowed(JobAction::kRequeue, JobState::kCancelled, true));
}

class JobServiceTest : public ::testing::Test {
 protected:
  // A job stored in state `s` (the scheduler does not run: nothing renders it). Priority 100 and at most one queued
  // job at a time, so that a claim takes this one.
  JobRecord job_in(JobState s) {
    JobRecord job = test::make_job(100, 1);
    sqlite_.create(job);
    const auto claim = [&] { ASSERT_EQ(sqlite_.claim_next(2).value().id, job.id); };
    switch (s) {
      case JobState::kQueued:
        break;
      case JobState::kRunning:
        claim();
        break;
      case JobState::kPaused:
        EXPECT_TRUE(sqlite_.transition(job.id, JobState::kPaused, 2, "", ""));
        break;
      case JobState::kSucceeded:
      case JobState::kFailed:
        claim();
        EXPECT_TRUE(sqlite_.transition(job.id, s, 3, "samples", s == JobState::kFailed ? "broken" : ""));
        break;
      case JobState::kCancelled:
        EXPECT_TRUE(sqlite_.transition(job.id, s, 3, "cancelled", ""));
        break;
    }
    return sqlite_.get(job.id, false).value();
  }

  test::TempDir dir_;
  SqliteJobStore sqlite_{dir_.path() / "jobs.db"};
  DirectoryJobFiles files_{dir_.path()};
  DirectoryAssetStore assets_{dir_.path()};
  ThreadPool pool_{1};
  Scheduler scheduler_{sqlite_, files_, pool_, SchedulerOptions{}};
  EventHub events_;
  Metrics metrics_;
  JobService jobs_{sqlite_, files_, assets_, scheduler_, events_, metrics_, JobServiceOptions{}};
  Caller admin_;
};

TEST_F(JobServiceTest, EveryStateOffersExactlyTheActionsItAccepts) {
  for (JobState s : kAllJobStates) {
    for (JobAction a : kAllJobActions) {
      if (a == JobAction::kDelete) continue;  // below: in every state
      SCOPED_TRACE(std::string(job_state_name(s)) + ", " + job_action_name(a));
      const JobRecord job = job_in(s);
      ASSERT_EQ(job.state, s);
      const json status = jobs_.status(job);
      const bool offered = offers(status, job_action_name(a));
      EXPECT_EQ(offered, action_allowed(a, s));
      if (action_target(a)) {
        EXPECT_EQ(status["links"].contains(job_action_name(a)), offered) << status.dump();
      }

      const auto answer = a == JobAction::kPriority ? jobs_.set_priority(admin_, job, 7) : jobs_.act(job, a);
      if (offered) {
        ASSERT_TRUE(std::holds_alternative<ActionTaken>(answer)) << std::get<Problem>(answer).detail;
        const JobRecord now = sqlite_.get(job.id, false).value();
        if (auto to = action_target(a))
          EXPECT_EQ(now.state, *to);
        else
          EXPECT_EQ(now.priority, 7);
      } else {
        ASSERT_TRUE(std::holds_alternative<Problem>(answer));
        EXPECT_EQ(std::get<Problem>(answer).status, 409);
        EXPECT_EQ(std::get<Problem>(answer).detail, action_refusal(a, s));
        const JobRecord now = sqlite_.get(job.id, false).value();
        EXPECT_EQ(now.state, s);
        EXPECT_EQ(now.priority, 100);
      }
      EXPECT_TRUE(offers(jobs_.status(sqlite_.get(job.id, false).value()), "delete"));
      EXPECT_TRUE(jobs_.remove(job.id));
      EXPECT_FALSE(sqlite_.get(job.id, false));
    }
  }
}

// A node that stopped after the store took its run's end, before it renamed the run's outputs, left them staged
// under the run's epoch: the first request for the result publishes them. Those of another epoch (a run whose end was
// refused) never are.
TEST_F(JobServiceTest, ASucceededJobsStagedResultIsPublishedWhenAsked) {
  const JobRecord job = job_in(JobState::kSucceeded);
  files_.prepare(job.id);
  const auto stage = [&](int64_t epoch, const std::string& bytes) {
    files_.stage(job.id, JobFile::kResultPng, epoch, bytes);
  };
  stage(job.epoch + 1, "the image of a run whose end was refused");
  EXPECT_TRUE(std::holds_alternative<Problem>(jobs_.result(job, JobFile::kResultPng)));
  EXPECT_FALSE(files_.read(job.id, JobFile::kResultPng));
  stage(job.epoch, "the image of the run that succeeded");
  auto answer = jobs_.result(job, JobFile::kResultPng);
  ASSERT_TRUE(std::holds_alternative<std::unique_ptr<FileReader>>(answer));
  EXPECT_EQ(files_.read(job.id, JobFile::kResultPng).value_or("(none)"), "the image of the run that succeeded");
  EXPECT_FALSE(files_.publish_staged(job.id, JobFile::kResultPng, job.epoch));  // published once
}

TEST_F(JobServiceTest, AJobThatFailedOnItsInputOffersOnlyDelete) {
  JobRecord job = test::make_job(100, 1);
  sqlite_.create(job);
  ASSERT_TRUE(sqlite_.claim_next(2));
  ASSERT_TRUE(
      sqlite_.transition(job.id, JobState::kFailed, 3, std::string(kInputRefused), "image 0 cannot be decoded"));
  job = sqlite_.get(job.id, false).value();
  const json status = jobs_.status(job);
  EXPECT_EQ(status["actions"], json({"delete"}));
  EXPECT_FALSE(status["links"].contains("requeue"));
  EXPECT_TRUE(status["stop_reason"].is_null());
  const auto answer = jobs_.act(job, JobAction::kRequeue);
  ASSERT_TRUE(std::holds_alternative<Problem>(answer));
  EXPECT_EQ(std::get<Problem>(answer).status, 409);
  EXPECT_EQ(std::get<Problem>(answer).detail, action_refusal(JobAction::kRequeue, JobState::kFailed, true));
  EXPECT_EQ(sqlite_.get(job.id, false).value().state, JobState::kFailed);
}

TEST_F(JobServiceTest, AUserSeesOnlyTheirOwnJobs) {
  JobRecord job = test::make_job(0, 1);
  job.owner = "ann";
  sqlite_.create(job);
  const Caller ann{"ann", false, true}, bob{"bob", false, true};
  EXPECT_TRUE(jobs_.find(ann, job.id));
  EXPECT_TRUE(jobs_.find(admin_, job.id));
  EXPECT_FALSE(jobs_.find(bob, job.id));
  EXPECT_FALSE(jobs_.find(ann, "../" + job.id));
  EXPECT_EQ(jobs_.list(ann, JobFilter{}).jobs.size(), 1u);
  EXPECT_EQ(jobs_.list(bob, JobFilter{}).jobs.size(), 0u);
}

// The real store, except that the end of a job, once written, is held back `hold` before the writer hears of it: the
// moment in which the job reads as ended but the render thread has not yet gone on.
class SlowEndStore final : public test::ForwardingStore {
 public:
  using ForwardingStore::ForwardingStore;
  std::atomic<bool> ended{false};
  std::chrono::milliseconds hold{600};

  bool end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms, const std::string& stop_reason,
               const std::string& error) override {
    const bool taken = inner_.end_run(id, epoch, to, now_ms, stop_reason, error);
    if (taken && is_terminal(to)) {
      ended = true;
      std::this_thread::sleep_for(hold);
    }
    return taken;
  }
};

TEST(JobServiceMetrics, AnEndedJobIsCountedAsSoonAsItReadsAsEnded) {
  test::TempDir dir;
  SqliteJobStore sqlite(dir.path() / "jobs.db");
  SlowEndStore store(sqlite);
  DirectoryJobFiles files(dir.path());
  DirectoryAssetStore assets(dir.path());
  ThreadPool pool(1);
  Scheduler scheduler(store, files, pool, SchedulerOptions{});
  EventHub events;
  Metrics metrics;
  JobService jobs(store, files, assets, scheduler, events, metrics, JobServiceOptions{});
  scheduler.start();

  auto checked = check_job_document(test::cornell_job(16, 1), SubmissionLimits{});
  auto submitted = jobs.submit(Caller{}, SubmitRequest{std::get<AcceptedJob>(checked), "", "", false});
  const std::string id = std::get<Submitted>(submitted).job.id;
  ASSERT_TRUE(test::eventually([&] { return store.ended.load(); }, 60));
  // What a client polling the job now reads, then what a scrape then says.
  ASSERT_EQ(sqlite.get(id, false).value().state, JobState::kSucceeded);
  const std::string text = metrics.render(Metrics::Gauges{});
  EXPECT_NE(text.find("tessera_job_duration_seconds_count 1\n"), std::string::npos) << text;
}

}  // namespace
}  // namespace tessera::server
