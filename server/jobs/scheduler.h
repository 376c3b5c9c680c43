// Runs jobs: claims queued jobs from the store up to `max_jobs` at once and has each rendered by its runner
// (render_work.h; in the daemon, a supervised worker process: worker_process.h), from a thread of its own that hears
// the render's reports. After each pass a render writes its checkpoint (the film, atomically) and a preview PNG, and
// the scheduler publishes its progress (in memory for status requests, and to the store); at the end the render stages
// the outputs the job asked for, and the scheduler records the end and publishes them. A job claimed with a checkpoint
// (the daemon stopped or died mid-render, or it was paused) resumes from it; sampling being deterministic, its image is
// the one an uninterrupted render gives. A job that throws fails alone, and a worker that crashes is retried up to
// `crash_retries` times: the daemon stays up. A store that fails while a job's end is recorded is retried until it
// takes it (JobStoreError never fails a job): the store, not the job, is at fault. An end the store's state machine
// refuses (the job was deleted, or changed elsewhere) is not recorded, and nothing is done as if it had been.
//
// A client's change of a job's state (cancel, pause, resume, requeue) is the job service's to decide and record
// (JobService::act): the store first, then, for a cancel or pause, a stop signal to the renders of the job here
// (stop()), which end within a tile's time and record nothing. A change made through another daemon on the same store
// reaches the renders here the same way, as a lease the store refuses.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "renderer/output.h"
#include "renderer/session.h"
#include "renderer/thread_pool.h"
#include "server/files/job_files.h"
#include "server/files/job_log.h"
#include "server/jobs/job_results.h"
#include "server/jobs/render_work.h"
#include "server/store/job_store.h"

namespace tessera::server {

struct SchedulerOptions {
  int max_jobs = 1;
  // Runs (jobs rendered whole, work units) one owner's jobs may hold at once across every node of the store; 0: no
  // limit (JobStore::claim_next).
  int max_running_per_user = 0;
  // Runs of a job that may be lost (its worker process crashed, or its node died while rendering it:
  // JobRecord::lost_runs) before it fails instead of rendering again: a scene that crashes the renderer fails after
  // this many retries, never in a loop.
  int crash_retries = 2;
  // Where renders run (render_work.h): the daemon's are supervised worker processes (WorkerProcessRunner). Unset: on
  // the run's own thread, with the scheduler's pool (InProcessRunner).
  std::shared_ptr<RenderRunner> runner;
  // This daemon's name among the nodes sharing the store, written on the lines it adds to job logs; empty for a
  // daemon alone.
  std::string node;
  // Maps an asset reference of a job ("gltf", "environment.map") to its file (SceneLoadOptions::resolve_asset).
  std::function<std::filesystem::path(const std::string& ref, const std::string& pointer)> resolve_asset;
  uint64_t max_gltf_instances = 1'000'000;  // SceneLoadOptions::max_gltf_instances
  // How often the queue is looked at without being woken (jobs another process may have added), and the leases of
  // the renders under way renewed: a render whose job was cancelled, paused or deleted elsewhere (another daemon on
  // the same store) finds out within this, when job_changed() does not tell it sooner.
  std::chrono::milliseconds poll_interval{1000};
  // How long a claim holds a job without being renewed (JobStore::claim_next): past it another daemon may take the
  // job over, and this one's writes for it are refused.
  std::chrono::milliseconds lease{kDefaultLeaseMs};
  // The wait before recording a job's end again after the store failed, doubled after each failure up to the max.
  std::chrono::milliseconds store_retry_first{100};
  std::chrono::milliseconds store_retry_max{5000};
};

// What the scheduler tells the rest of the daemon (events, metrics). Called on render threads; must not block long.
struct SchedulerHooks {
  std::function<void(const std::string& id)> state_changed;
  std::function<void(const std::string& id, const JobProgress& progress)> progress;
  std::function<void(const std::string& id, uint32_t pass)> preview;
  std::function<void(uint64_t pixel_samples)> samples_rendered;
  // Records the end of a job (succeeded, failed or cancelled): runs `record`, the store's state change (true when the
  // store took it), and counts the render time in the same step (Metrics::record_job_end). Unset: `record` alone.
  std::function<bool(double render_s, const std::function<bool()>& record)> job_ended;
  // A write to the job store failed (a job's progress, warnings or end).
  std::function<void()> store_write_failed;
};

class Scheduler {
 public:
  Scheduler(JobStore& store, const JobFiles& files, ThreadPool& pool, SchedulerOptions options);
  ~Scheduler();
  Scheduler(const Scheduler&) = delete;
  Scheduler& operator=(const Scheduler&) = delete;

  void set_hooks(SchedulerHooks hooks);
  // Puts jobs a previous process left running back in the queue (they resume from their checkpoints), then starts
  // claiming.
  void start();
  // A job was queued: look at the queue now.
  void wake();
  // Stops claiming and asks every render to end its pass (which checkpoints); returns at once.
  void begin_drain();
  // Stops claiming, lets running renders end their pass for up to `grace_s` seconds, then cancels the rest; their
  // jobs go back to the queue with their checkpoints. Waits for the threads.
  void shutdown(double grace_s = 0);
  bool accepting() const;

  // A job changed in the store, here or on another daemon (its state, priority or lease; PostgresNotifications): a
  // render of it here checks its lease now, rather than at its next renewal, and stops within a tile's time if the
  // job was cancelled, paused, deleted or taken over. `claimable` (it is queued): the queue is looked at now.
  void job_changed(const std::string& id, bool claimable);
  // Changes may have been missed (the store's notifications were down): every render checks its lease now, and the
  // queue is looked at.
  void recheck();

  // The progress of a job rendering here, fresher than the store's.
  std::optional<JobProgress> live_progress(const std::string& id) const;
  int running_count() const;
  // Whether the end of a job is waiting for the store to take it (its last write failed).
  bool store_failing() const;

  // Holds off this daemon's claims while it lives: a job a client is changing (a queued job being cancelled, say) is
  // not claimed here between the change's read of the job and its write.
  class ClaimHold {
   public:
    explicit ClaimHold(Scheduler& scheduler);
    ~ClaimHold();
    ClaimHold(const ClaimHold&) = delete;
    ClaimHold& operator=(const ClaimHold&) = delete;

   private:
    Scheduler& scheduler_;
  };
  [[nodiscard]] ClaimHold hold_claims() { return ClaimHold(*this); }

  // What a client's change, recorded in the store already, asks of the renders of its job here.
  enum class StopSignal { kCancel, kPause };
  // Signals every render of `id` here (a job rendered whole, or units of a split job) to end within a tile's time,
  // recording nothing: a cancelled one gives up its pass under way; a paused job rendered whole ends its pass and
  // keeps it as its checkpoint (its units give theirs up). Nothing for a job not rendering here. Returns how many
  // renders were signalled.
  int stop(const std::string& id, StopSignal signal);

  // Deletes a job and its files (cancelling its render first); false for an unknown id. With
  // `only_finished_before_ms` (retention), only a job that ended before that time and has no render thread left;
  // anything else is kept (false).
  bool remove(const std::string& id, std::optional<int64_t> only_finished_before_ms = std::nullopt);

 private:
  class RenderSlot;
  struct Run;
  class RunReport;
  void dispatch_loop();
  // A claimed run, on its own thread: a render (render_run), a split job's merge, or the failure of a job lost too
  // often; then finish_run().
  void run_job(const std::shared_ptr<RenderSlot>& slot, const JobRecord& record);
  void finish_run(RenderSlot& slot);
  // A render, wherever the runner runs it (render_work.h): load, restore (resumed), passes (publish_pass after
  // each), then its end (end_rendered, end_interrupted, record_failure or end_crashed), all reported through a
  // RunReport on the run's thread.
  void render_run(RenderSlot& slot, const JobRecord& record);
  void end_run_reported(Run& run, const RunEnd& end);
  void record_warnings(const std::string& id, const std::vector<std::string>& warnings);
  void log_start(const Run& run);
  // A pass ended, its checkpoint and preview written (unless `write_error`): its progress, in memory, in the store
  // and to the hooks.
  void publish_pass(Run& run, const RenderProgress& progress, const std::string& write_error);
  bool still_ours_before_outputs(RenderSlot& slot);
  void end_interrupted(RenderSlot& slot, const JobRecord& record, uint32_t samples_done);
  // The lines a render stopped by a client's change (stop()) adds to the logs; it records nothing.
  void log_settled(const JobRecord& record, StopSignal signal, uint32_t samples_done);
  // A render whose lease the store refused: it records nothing, and the job's files go if the job is gone.
  void end_taken_away(const std::string& id, uint32_t samples_done);
  void end_stopping(RenderSlot& slot, const std::string& id, uint32_t samples_done);
  // A unit rendered its range (its film kept): its end recorded, the split job's preview refined.
  void end_unit(Run& run, const RunEnd& end);
  // A job rendered whole (its outputs staged): its end recorded, its outputs published.
  void end_job(Run& run, const RunEnd& end);
  // The process rendering the run died (RunOutcome::kCrashed): the job is taken over from its last checkpoint, here
  // or on another node, counting a lost run; past options_.crash_retries it fails, naming the crash.
  void end_crashed(RenderSlot& slot, const JobRecord& record, const RunEnd& end);
  bool record_end(RenderSlot& slot, const std::function<bool()>& write);
  bool record_terminal(RenderSlot& slot, JobState to, double render_s, const std::string& stop_reason,
                       const std::string& error = "", const std::function<void()>& before = nullptr);
  bool record_failure(RenderSlot& slot, const std::string& message, double render_s, bool input_refused);
  // The run read its checkpoint (RunListener::resumed): the log says what it resumed from, and the progress it holds
  // is recorded at once, not at the end of the next pass, so that a job resumed after a restart does not read 0
  // samples done meanwhile.
  void resumed(Run& run, const std::optional<RenderProgress>& restored, bool unusable);
  // Fails a job claimed after more lost runs than options_.crash_retries, naming them; it is not rendered again.
  void fail_lost_too_often(RenderSlot& slot, const JobRecord& record);
  void count_store_error();
  void reap_finished_locked(std::unique_lock<std::mutex>& lock);
  void renew_leases_locked();
  // How often a render's lease is renewed: the store's renewal period for the lease, or the poll interval if shorter.
  std::chrono::milliseconds renewal_period() const;
  // `noticed_by`: what found the lease gone, for the log (a notification, a renewal, a refused write).
  void renew_lease_locked(RenderSlot& slot, const char* noticed_by);
  void lose_lease_locked(RenderSlot& slot, const char* noticed_by);
  void notify_state(const std::string& id);
  // The slots of a job here (several for the units of a split job); those still rendering.
  std::vector<RenderSlot*> slots_locked(const std::string& id) const;
  std::vector<RenderSlot*> rendering_locked(const std::string& id) const;
  // A split job's units rendered: merges their films (each a unit's authoritative checkpoint) into the job's outputs
  // and records its end (the merge unit's run, fenced by its epoch).
  void merge_units(RenderSlot& slot, const JobRecord& record);
  // The end unit of a frame range: every frame's files are there; the job succeeds.
  void finish_frames(RenderSlot& slot, const JobRecord& record);
  // After the end of a run that staged its outputs: published when the store took that end (`recorded`, or read back
  // when it is unknown), removed when it refused it.
  void publish_outputs(RenderSlot& slot, bool recorded);

  JobStore& store_;
  const JobFiles& files_;
  JobLog log_;  // each job's own log, among its files
  JobResults results_;
  ThreadPool& pool_;
  SchedulerOptions options_;
  std::shared_ptr<RenderRunner> runner_;
  SchedulerHooks hooks_;

  mutable std::mutex mutex_;
  std::condition_variable cv_;
  bool started_ = false;
  bool stopping_ = false;
  int claims_held_ = 0;  // ClaimHolds alive: no claim while above 0
  std::map<std::string, std::shared_ptr<RenderSlot>> running_;
  std::thread dispatcher_;
};

}  // namespace tessera::server
