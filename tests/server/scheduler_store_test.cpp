// The scheduler when the job store fails as it records the end of a job (a full disk, a locked database): the
// render's outcome stands and is written again until the store takes it, so the job neither fails for it nor stays
// running; a stop meanwhile returns at once and leaves the job running in the store, for the next start to resume.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <climits>
#include <functional>
#include <memory>
#include <mutex>
#include <variant>

#include "renderer/film.h"
#include "renderer/thread_pool.h"
#include "server/files/assets.h"
#include "server/files/events.h"
#include "server/files/job_files.h"
#include "server/jobs/checkpoint.h"
#include "server/jobs/job_service.h"
#include "server/jobs/metrics.h"
#include "server/jobs/scheduler.h"
#include "server/jobs/submission.h"
#include "server/store/sqlite_job_store.h"
#include "tests/server/forwarding_store.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// The real SQLite store, except that a state change other than a claim (the end of a run: succeeded, failed,
// cancelled, paused, back to queued; a client's requeue) throws JobStoreError while `failures_left` is above zero, as
// SQLITE_FULL would, and a removal while `remove_failures_left` is.
class FailingEndStore final : public test::ForwardingStore {
 public:
  using ForwardingStore::ForwardingStore;

  std::atomic<int> failures_left{0};
  std::atomic<int> failures{0};  // transitions refused so far
  std::atomic<int> remove_failures_left{0};

  bool transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                  const std::string& error, std::optional<JobState> only_from) override {
    if (to != JobState::kRunning) fail();
    return inner_.transition(id, to, now_ms, stop_reason, error, only_from);
  }
  // Runs after each lease renewal the store took (to change the job "elsewhere" right after it).
  std::function<void(const std::string& id)> after_renewal;

  bool renew_lease(const std::string& id, int64_t epoch, int64_t now_ms, int64_t lease_ms) override {
    const bool taken = inner_.renew_lease(id, epoch, now_ms, lease_ms);
    if (taken && after_renewal) after_renewal(id);
    return taken;
  }
  std::atomic<int> ends{0};  // ends of runs asked for (end_run), taken or not
  bool end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms, const std::string& stop_reason,
               const std::string& error) override {
    ends.fetch_add(1);
    fail();
    return inner_.end_run(id, epoch, to, now_ms, stop_reason, error);
  }
  void fail() {
    if (failures_left.load() > 0) {
      failures_left.fetch_sub(1);
      failures.fetch_add(1);
      throw JobStoreError("job store: step: database or disk is full", true);
    }
  }
  // Called after each read of a job, with its id: another node acting between this node's read and its next step.
  std::function<void(const std::string&)> after_get;
  std::optional<JobRecord> get(const std::string& id, bool with_document) override {
    std::optional<JobRecord> job = inner_.get(id, with_document);
    if (after_get) after_get(id);
    return job;
  }
  bool remove(const std::string& id, std::optional<int64_t> only_finished_before_ms) override {
    if (remove_failures_left.load() > 0) {
      remove_failures_left.fetch_sub(1);
      throw JobStoreError("job store: step: database is locked", false);
    }
    return inner_.remove(id, only_finished_before_ms);
  }
};

class SchedulerStoreFailure : public ::testing::Test {
 protected:
  // One job at a time; the store's retries wait `first_retry`, doubling up to four times that.
  std::unique_ptr<Scheduler> make_scheduler(std::chrono::milliseconds first_retry,
                                            std::chrono::milliseconds poll_interval = 1000ms) {
    SchedulerOptions options;
    options.poll_interval = poll_interval;
    options.store_retry_first = first_retry;
    options.store_retry_max = first_retry * 4;
    auto scheduler = std::make_unique<Scheduler>(store_, files_, pool_, options);
    SchedulerHooks hooks;
    hooks.store_write_failed = [this] { store_errors_.fetch_add(1); };
    scheduler->set_hooks(std::move(hooks));
    return scheduler;
  }

  // Queues the Cornell box at 16x16 and 1 spp (a few milliseconds of rendering) as POST /v1/jobs would.
  std::string queue_tiny_job() { return queue_job(test::cornell_job(16, 1)); }

  std::string queue_job(const nlohmann::json& doc) {
    const JobRecord job = test::accepted_job_record(doc);
    sqlite_.create(job);
    return job.id;
  }

  // The job service over this store and `scheduler`, as the daemon has it: a client's actions go through it. It
  // installs its own hooks on the scheduler.
  std::unique_ptr<JobService> make_service(Scheduler& scheduler) {
    return std::make_unique<JobService>(store_, files_, assets_, scheduler, events_, metrics_, JobServiceOptions{});
  }

  // A client's action on job `id`, through `service`.
  std::variant<ActionTaken, Problem> act(JobService& service, const std::string& id, JobAction action) {
    return service.act(sqlite_.get(id, false).value(), action);
  }

  JobState state_of(const std::string& id) { return sqlite_.get(id, false).value().state; }

  bool has_ended(const std::string& id) {
    const JobState s = state_of(id);
    return s != JobState::kQueued && s != JobState::kRunning;
  }

  test::TempDir dir_;
  SqliteJobStore sqlite_{dir_.path() / "jobs.db"};
  FailingEndStore store_{sqlite_};
  DirectoryJobFiles files_{dir_.path()};
  ThreadPool pool_{2};
  DirectoryAssetStore assets_{dir_.path()};
  EventHub events_;
  Metrics metrics_;
  std::atomic<int> store_errors_{0};
};

TEST_F(SchedulerStoreFailure, ASucceededJobIsRecordedOnceTheStoreRecovers) {
  store_.failures_left = 3;
  auto scheduler = make_scheduler(1ms);
  const std::string id = queue_tiny_job();
  scheduler->start();

  ASSERT_TRUE(test::eventually([&] { return has_ended(id); }, 120)) << job_state_name(state_of(id));
  const JobRecord job = sqlite_.get(id, false).value();
  EXPECT_EQ(job.state, JobState::kSucceeded) << job.error;  // not failed for the store's fault
  EXPECT_EQ(job.error, "");
  EXPECT_EQ(job.stop_reason, "samples");
  EXPECT_EQ(job.progress.samples_done, 1u);  // the final progress, written with the end
  EXPECT_EQ(store_.failures.load(), 3);
  EXPECT_EQ(store_errors_.load(), 3);  // each counted (tessera_job_store_errors_total)
  EXPECT_TRUE(fs::is_regular_file(files_.path(id, JobFile::kResultPng)));
  EXPECT_FALSE(fs::exists(files_.path(id, JobFile::kCheckpoint)));  // removed once the end is recorded
  EXPECT_FALSE(scheduler->store_failing());
  scheduler->shutdown();
}

// Another node cancels the job between the render's last lease check and its end: it keeps the partial results
// written by the cancelling node, and the render's full image, whose end the store refuses, is never published.
TEST_F(SchedulerStoreFailure, ACancelAfterTheLastLeaseCheckKeepsThePartialResults) {
  const std::string partial = "the partial results the cancelling node wrote";
  std::atomic<int> cancels{0};
  store_.after_renewal = [&](const std::string& id) {
    // The render's check before its outputs: its one pass is done (the dispatcher renews only hourly here).
    if (sqlite_.get(id, false).value().progress.samples_done != 1 || cancels.fetch_add(1) > 0) return;
    files_.write(id, JobFile::kResultPng, partial);  // what a cancel publishes, then its change of state
    EXPECT_TRUE(sqlite_.transition(id, JobState::kCancelled, 2, "cancelled", "", std::nullopt));
  };
  auto scheduler = make_scheduler(1ms, std::chrono::hours(1));
  const std::string id = queue_tiny_job();
  scheduler->start();

  ASSERT_TRUE(test::eventually([&] { return cancels.load() > 0 && scheduler->running_count() == 0; }, 120));
  EXPECT_EQ(state_of(id), JobState::kCancelled);
  EXPECT_EQ(files_.read(id, JobFile::kResultPng).value_or("(none)"), partial);
  EXPECT_FALSE(files_.read(id, JobFile::kResultExr));  // the canceller kept no EXR: none of the render's either
  for (const auto& entry : fs::directory_iterator(files_.dir(id))) {  // nothing staged is left behind
    const std::string name = entry.path().filename().string();
    EXPECT_FALSE(name.starts_with("result.e") && name != "result.exr") << name;
  }
  scheduler->shutdown();
}

TEST_F(SchedulerStoreFailure, AStopWhileTheStoreFailsLeavesTheJobRunningForTheNextStart) {
  store_.failures_left = INT_MAX;
  // After the first failure the retry waits a minute: only the stop can end the wait.
  auto scheduler = make_scheduler(60s);
  const std::string first = queue_tiny_job();
  const std::string second = queue_tiny_job();
  scheduler->start();

  ASSERT_TRUE(test::eventually([&] { return scheduler->store_failing(); }, 120));
  // The slot stays taken while the store is retried: the second job waits (max_jobs 1).
  EXPECT_EQ(scheduler->running_count(), 1);
  EXPECT_EQ(state_of(second), JobState::kQueued);
  EXPECT_EQ(store_errors_.load(), 1);

  const auto stop_started = std::chrono::steady_clock::now();
  scheduler->shutdown();
  EXPECT_LT(std::chrono::steady_clock::now() - stop_started, 30s);  // well before the minute's retry
  EXPECT_EQ(store_.failures.load(), 1);
  EXPECT_EQ(state_of(first), JobState::kRunning);
  EXPECT_TRUE(fs::is_regular_file(files_.path(first, JobFile::kCheckpoint)));  // kept for the resume
  scheduler.reset();

  // The next start, the store healthy again: the job is requeued and resumes from its checkpoint; the other follows.
  store_.failures_left = 0;
  auto next = make_scheduler(1ms);
  next->start();
  ASSERT_TRUE(test::eventually([&] { return has_ended(first) && has_ended(second); }, 120));
  EXPECT_EQ(state_of(first), JobState::kSucceeded);
  EXPECT_EQ(state_of(second), JobState::kSucceeded);
  EXPECT_EQ(sqlite_.get(first, false)->progress.samples_done, 1u);
  EXPECT_FALSE(fs::exists(files_.path(first, JobFile::kCheckpoint)));
  next->shutdown();
}

// A client's DELETE of a rendering job that the store refuses (answered 503, to be retried) changes nothing: the
// render goes on and its files stay. Were the render stopped first, the store would keep the job running with
// nothing rendering it, its files gone.
TEST_F(SchedulerStoreFailure, ADeleteTheStoreRefusesLeavesTheRenderGoing) {
  auto scheduler = make_scheduler(1ms);
  const std::string id = queue_job(test::long_cornell_job());
  scheduler->start();
  auto passes = [&]() -> uint32_t {
    auto p = scheduler->live_progress(id);
    return p ? p->passes : 0;
  };
  ASSERT_TRUE(test::eventually([&] { return passes() >= 1; }, 120));

  store_.remove_failures_left = 1;
  EXPECT_THROW(scheduler->remove(id), JobStoreError);
  const uint32_t at_failure = passes();
  EXPECT_TRUE(test::eventually([&] { return passes() >= at_failure + 2; }, 30)) << "the render stopped";
  EXPECT_EQ(state_of(id), JobState::kRunning);
  EXPECT_TRUE(fs::is_regular_file(files_.path(id, JobFile::kCheckpoint)));

  // The retry deletes it.
  EXPECT_TRUE(scheduler->remove(id));
  EXPECT_FALSE(sqlite_.get(id, false));
  ASSERT_TRUE(test::eventually([&] { return scheduler->running_count() == 0 && !fs::exists(files_.dir(id)); }, 120));
  scheduler->shutdown();
}

// A requeue the store refuses keeps the job as it was, the preview of its last run included.
TEST_F(SchedulerStoreFailure, ARequeueTheStoreRefusesKeepsTheLastRun) {
  auto scheduler = make_scheduler(1ms);  // not started: nothing claims the job
  const std::string id = queue_tiny_job();
  ASSERT_TRUE(sqlite_.transition(id, JobState::kCancelled, 2, "cancelled", ""));
  fs::create_directories(files_.dir(id));
  files_.write(id, JobFile::kPreviewPng, "a preview");

  auto service = make_service(*scheduler);
  store_.failures_left = 1;
  EXPECT_THROW(act(*service, id, JobAction::kRequeue), JobStoreError);
  EXPECT_EQ(state_of(id), JobState::kCancelled);
  EXPECT_TRUE(fs::is_regular_file(files_.path(id, JobFile::kPreviewPng)));

  EXPECT_TRUE(std::holds_alternative<ActionTaken>(act(*service, id, JobAction::kRequeue)));
  EXPECT_EQ(state_of(id), JobState::kQueued);
  EXPECT_FALSE(fs::exists(files_.path(id, JobFile::kPreviewPng)));  // from scratch
}

}  // namespace
}  // namespace tessera::server

namespace tessera::server {
namespace {

// A cancel that loses the race with the run's own end on another node: the job succeeded between the canceller's read
// of it and its change of state, which the store then refuses. The finished image stays: the canceller's older
// partial image (from the checkpoint it read) is never published over it, and nothing it staged is left behind.
TEST_F(SchedulerStoreFailure, ACancelRefusedBecauseTheJobSucceededLeavesItsFinishedImage) {
  const std::string id = queue_tiny_job();
  const JobRecord run = sqlite_.claim_next(1, 3'600'000).value();  // the other node's run
  ASSERT_EQ(run.id, id);
  files_.prepare(id);
  Film film(16, 16);
  film.add_sample(3, 4, Rgb(0.5f, 0.25f, 1.0f));
  film.set_samples(1);
  files_.write(id, JobFile::kCheckpoint, encode_checkpoint(film, 1, 0.1, fnv1a64(run.settings)));
  const std::string finished = "the other node's finished image";
  std::atomic<bool> armed{true};
  store_.after_get = [&](const std::string& job_id) {
    if (job_id != id || !armed.exchange(false)) return;
    EXPECT_TRUE(sqlite_.end_run(id, run.epoch, JobState::kSucceeded, 2, "samples", ""));
    files_.write(id, JobFile::kResultPng, finished);  // its checkpoint, removed next, is still there to read
  };
  auto scheduler = make_scheduler(1ms);  // not started: it renders nothing of this job
  auto service = make_service(*scheduler);

  const auto answer = service->act(run, JobAction::kCancel);
  ASSERT_TRUE(std::holds_alternative<Problem>(answer));
  EXPECT_EQ(std::get<Problem>(answer).status, 409);
  EXPECT_FALSE(armed.load());  // the other node did end the run in between
  EXPECT_EQ(state_of(id), JobState::kSucceeded);
  EXPECT_EQ(files_.read(id, JobFile::kResultPng).value_or("(none)"), finished);
  EXPECT_FALSE(files_.read(id, JobFile::kResultExr));
  for (const auto& entry : fs::directory_iterator(files_.dir(id))) {
    const std::string name = entry.path().filename().string();
    EXPECT_FALSE(name.starts_with("result.e") && name != "result.exr") << name;
  }
}

// A job resumed from its checkpoint reports the checkpoint's progress at once: the first progress the next run
// gives is the checkpoint's (same passes and samples), not the end of a new pass, so a status read after a restart
// never says 0 samples done for a job with hundreds rendered.
TEST_F(SchedulerStoreFailure, AResumedJobReportsItsCheckpointsProgressBeforeItsNextPass) {
  const std::string id = queue_job(test::cornell_job(32, 65536));
  std::mutex mutex;
  std::optional<JobProgress> last, first_resumed;
  auto first = make_scheduler(1ms, 20ms);
  SchedulerHooks hooks;
  hooks.progress = [&](const std::string&, const JobProgress& p) {
    std::lock_guard lock(mutex);
    last = p;
  };
  first->set_hooks(std::move(hooks));
  first->start();
  ASSERT_TRUE(test::eventually(
      [&] {
        std::lock_guard lock(mutex);
        return last && last->passes >= 3;
      },
      120));
  first->shutdown();  // back in the queue, its checkpoint kept
  first.reset();
  ASSERT_EQ(state_of(id), JobState::kQueued);
  const JobProgress checkpointed = *last;

  auto second = make_scheduler(1ms, 20ms);
  SchedulerHooks resumed_hooks;
  resumed_hooks.progress = [&](const std::string&, const JobProgress& p) {
    std::lock_guard lock(mutex);
    if (!first_resumed) first_resumed = p;
  };
  second->set_hooks(std::move(resumed_hooks));
  second->start();
  ASSERT_TRUE(test::eventually(
      [&] {
        std::lock_guard lock(mutex);
        return first_resumed.has_value();
      },
      120));
  second->shutdown();
  EXPECT_EQ(first_resumed->passes, checkpointed.passes);
  EXPECT_EQ(first_resumed->samples_done, checkpointed.samples_done);
  EXPECT_GT(first_resumed->samples_done, 0u);
}

// A job stored before the settings had one mapping: its record holds the text that version wrote for its document
// (captured from it: 32x32, 65536 spp, EXR only, in float), which the scheduler reads for the run's settings and
// fingerprints its checkpoints with. It renders, resumes from its checkpoint after a stop, and writes the outputs
// the text asks for.
TEST_F(SchedulerStoreFailure, AJobStoredWithTheEarlierSettingsTextRunsAndResumes) {
  nlohmann::json doc = test::cornell_job(32, 65536);
  doc["render"]["exr_precision"] = "float";
  doc["outputs"] = {"exr"};
  JobRecord job = test::accepted_job_record(doc);
  job.settings =
      R"({"estimator":"mis","exposure_ev":0.0,"exr_precision":"float","height":32,"integrator":"path","max_depth":8,)"
      R"("noise_target":0.0,"sampler":"sobol","seed":1,"spp":65536,"time_limit_s":0.0,"tonemap":"clamp","width":32})";
  job.outputs = R"(["exr"])";
  EXPECT_EQ(test::accepted_job_record(doc).settings, job.settings);  // what the mapping writes today too
  sqlite_.create(job);
  std::mutex mutex;
  std::optional<JobProgress> last, first_resumed;
  auto first = make_scheduler(1ms, 20ms);
  SchedulerHooks hooks;
  hooks.progress = [&](const std::string&, const JobProgress& p) {
    std::lock_guard lock(mutex);
    last = p;
  };
  first->set_hooks(std::move(hooks));
  first->start();
  ASSERT_TRUE(test::eventually(
      [&] {
        std::lock_guard lock(mutex);
        return last && last->passes >= 2;
      },
      120));
  first->shutdown();
  first.reset();
  ASSERT_EQ(state_of(job.id), JobState::kQueued);
  const JobProgress checkpointed = *last;

  auto second = make_scheduler(1ms, 20ms);
  auto service = make_service(*second);  // for the cancel below; the test's own hooks replace the service's
  SchedulerHooks resumed_hooks;
  resumed_hooks.progress = [&](const std::string&, const JobProgress& p) {
    std::lock_guard lock(mutex);
    if (!first_resumed) first_resumed = p;
  };
  second->set_hooks(std::move(resumed_hooks));
  second->start();
  ASSERT_TRUE(test::eventually(
      [&] {
        std::lock_guard lock(mutex);
        return first_resumed.has_value();
      },
      120));
  EXPECT_EQ(first_resumed->samples_done, checkpointed.samples_done);  // its checkpoint matched its settings
  ASSERT_TRUE(std::holds_alternative<ActionTaken>(act(*service, job.id, JobAction::kCancel)));
  ASSERT_TRUE(test::eventually([&] { return has_ended(job.id); }, 120));
  second->shutdown();
  EXPECT_EQ(state_of(job.id), JobState::kCancelled);
  // Its partial results: the formats the stored outputs name.
  EXPECT_TRUE(files_.read(job.id, JobFile::kResultExr));
  EXPECT_FALSE(files_.read(job.id, JobFile::kResultPng));
}

// A client's cancel of a job rendering here is the job service's to decide and record: the job is cancelled, with its
// partial results, when the call returns, and the render only receives the stop signal: it winds down and records no
// end of its own. No checkpoint survives, not even one whose pass was being written while the service removed it.
TEST_F(SchedulerStoreFailure, TheServiceRecordsACancelAndTheRenderOnlyStops) {
  auto scheduler = make_scheduler(1ms);
  auto service = make_service(*scheduler);
  const std::string id = queue_job(test::long_cornell_job());
  scheduler->start();
  ASSERT_TRUE(test::eventually(
      [&] {
        auto p = scheduler->live_progress(id);
        return p && p->passes >= 1;
      },
      120));

  const auto answer = act(*service, id, JobAction::kCancel);
  ASSERT_TRUE(std::holds_alternative<ActionTaken>(answer)) << std::get<Problem>(answer).detail;
  const ActionTaken& taken = std::get<ActionTaken>(answer);
  EXPECT_EQ(taken.job.state, JobState::kCancelled);
  EXPECT_TRUE(files_.read(id, JobFile::kResultPng));  // the image of its last complete pass

  ASSERT_TRUE(test::eventually([&] { return scheduler->running_count() == 0; }, 120));
  EXPECT_FALSE(fs::exists(files_.path(id, JobFile::kCheckpoint)));
  EXPECT_EQ(store_.ends.load(), 0);  // the render recorded nothing
  EXPECT_EQ(state_of(id), JobState::kCancelled);
  EXPECT_EQ(sqlite_.get(id, false)->stop_reason, "cancelled");
  scheduler->shutdown();
}

// As a cancel: the job is paused when the call returns, the render stops recording nothing, and the checkpoint of its
// last complete pass stays for its resume.
TEST_F(SchedulerStoreFailure, TheServiceRecordsAPauseAndTheRenderKeepsItsCheckpoint) {
  auto scheduler = make_scheduler(1ms);
  auto service = make_service(*scheduler);
  const std::string id = queue_job(test::long_cornell_job());
  scheduler->start();
  ASSERT_TRUE(test::eventually([&] { return sqlite_.get(id, false)->progress.passes >= 1; }, 120));

  const auto answer = act(*service, id, JobAction::kPause);
  ASSERT_TRUE(std::holds_alternative<ActionTaken>(answer)) << std::get<Problem>(answer).detail;
  EXPECT_EQ(std::get<ActionTaken>(answer).job.state, JobState::kPaused);
  ASSERT_TRUE(test::eventually([&] { return scheduler->running_count() == 0; }, 120));
  EXPECT_EQ(store_.ends.load(), 0);
  EXPECT_EQ(state_of(id), JobState::kPaused);
  EXPECT_GT(sqlite_.get(id, false)->progress.samples_done, 0u);
  EXPECT_TRUE(fs::is_regular_file(files_.path(id, JobFile::kCheckpoint)));
  scheduler->shutdown();
}

// The scheduler's stop is a signal to the renders here, nothing more: for a job it does not render, the store and the
// job's files stay as they were.
TEST_F(SchedulerStoreFailure, AStopForAJobNotRenderingHereChangesNothing) {
  auto scheduler = make_scheduler(1ms);  // not started: nothing renders
  const std::string id = queue_tiny_job();
  EXPECT_EQ(scheduler->stop(id, Scheduler::StopSignal::kCancel), 0);
  EXPECT_EQ(scheduler->stop(id, Scheduler::StopSignal::kPause), 0);
  EXPECT_EQ(state_of(id), JobState::kQueued);
  EXPECT_FALSE(fs::exists(files_.dir(id)));
}

}  // namespace
}  // namespace tessera::server
