#include "server/jobs/scheduler.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstdio>
#include <system_error>

#include <nlohmann/json.hpp>

#include "renderer/job.h"
#include "renderer/output.h"
#include "renderer/scene.h"
#include "renderer/scene_error.h"
#include "renderer/session.h"
#include "server/base/file_io.h"
#include "server/base/log.h"
#include "server/base/time_format.h"
#include "server/jobs/checkpoint.h"

namespace tessera::server {

using nlohmann::json;

// One job rendering here. Guarded by the scheduler's mutex, except `thread`, which only the dispatcher touches.
class Scheduler::RenderSlot {
 public:
  std::string id;
  int unit = -1;                  // the work unit it renders (JobRecord::unit); -1: the whole job
  RunControl control;             // stops its render (or its load), wherever the render runs
  bool delete_requested = false;  // by a client: the job is gone, its files go when the render stops
  std::optional<JobProgress> progress;
  bool awaiting_store = false;  // its end is rendered but the store failed to record it; retried
  bool ending = false;          // its end is being recorded: its lease is no longer renewed nor checked
  int64_t epoch = 0;            // of its lease: every write of the run carries it
  bool lease_lost = false;      // the store refused the lease: the job was taken over or changed elsewhere
  // A client's cancel or pause that the store took first (Scheduler::stop()): the render stops and records nothing.
  std::optional<StopSignal> settled;
  std::chrono::steady_clock::time_point renewed_at = std::chrono::steady_clock::now();
  bool done = false;
  std::thread thread;

  // Ends the scene's load, or the render's pass under way, within a tile's time; the last checkpoint stays.
  void abandon() { control.cancel(); }
  // A client's change, recorded in the store, stops the render (Scheduler::stop()). A paused job rendered whole ends
  // its pass and keeps it as its checkpoint; anything else gives up its pass under way (a unit's would not count:
  // the store takes a unit's checkpoint only from a run still running).
  void signal(StopSignal s) {
    settled = s;
    if (s == StopSignal::kPause && unit < 0)
      control.stop();
    else
      control.cancel();
  }
};

namespace {

// "frames 5-8" (consecutive numbers of the range), "frame 5".
std::string describe_frames(const std::vector<int64_t>& frames) {
  if (frames.empty()) return "no frames";
  if (frames.size() == 1) return "frame " + std::to_string(frames.front());
  return "frames " + std::to_string(frames.front()) + "-" + std::to_string(frames.back());
}

// printf into a std::string, for the lines of a job's log.
template <typename... Args>
std::string printf_string(const char* pattern, Args... args) {
  char buf[512];
  std::snprintf(buf, sizeof buf, pattern, args...);
  return buf;
}

// Why a render that completed stopped, as its log says it.
std::string stop_explained(StopReason r) {
  switch (r) {
    case StopReason::kSamples:
      return "its samples-per-pixel budget was reached";
    case StopReason::kTimeLimit:
      return "its time limit was reached";
    case StopReason::kNoiseTarget:
      return "its noise target was reached";
    case StopReason::kAdaptiveThreshold:
      return "adaptive sampling stopped every pixel below its threshold";
    case StopReason::kStopped:
    case StopReason::kCancelled:
      break;
  }
  return stop_reason_name(r);
}

JobProgress to_job_progress(const RenderProgress& p) {
  JobProgress jp;
  jp.passes = p.pass;
  jp.samples_done = p.samples_done;
  jp.samples_total = p.samples_total;
  jp.elapsed_s = p.elapsed_s;
  jp.eta_s = p.eta_s;
  jp.samples_per_s = p.samples_per_s;
  return jp;
}

}  // namespace

Scheduler::Scheduler(JobStore& store, const JobFiles& files, ThreadPool& pool, SchedulerOptions options)
    : store_(store),
      files_(files),
      log_(files, options.node),
      results_(store, files, options.node),
      pool_(pool),
      options_(std::move(options)),
      runner_(options_.runner) {
  if (!runner_) {
    RenderEnvironment env;
    env.files = &files_;
    env.pool = &pool_;
    env.resolve_asset = options_.resolve_asset;
    env.max_gltf_instances = options_.max_gltf_instances;
    runner_ = std::make_shared<InProcessRunner>(std::move(env));
  }
}

Scheduler::ClaimHold::ClaimHold(Scheduler& scheduler) : scheduler_(scheduler) {
  // Claims happen under the mutex: once it is held, none is under way.
  std::lock_guard lock(scheduler_.mutex_);
  ++scheduler_.claims_held_;
}

Scheduler::ClaimHold::~ClaimHold() {
  {
    std::lock_guard lock(scheduler_.mutex_);
    --scheduler_.claims_held_;
  }
  scheduler_.cv_.notify_all();
}

Scheduler::~Scheduler() {
  shutdown();
}

void Scheduler::set_hooks(SchedulerHooks hooks) {
  std::lock_guard lock(mutex_);
  hooks_ = std::move(hooks);
}

void Scheduler::notify_state(const std::string& id) {
  if (!hooks_.state_changed) return;
  // On a render thread nothing above catches: a hook that cannot read a failing store costs the event, not the
  // process.
  try {
    hooks_.state_changed(id);
  } catch (const std::exception& e) {
    if (dynamic_cast<const JobStoreError*>(&e)) count_store_error();
    log(LogLevel::kWarn, "cannot publish the state of a job", {{"job", id}, {"error", e.what()}});
  }
}

void Scheduler::count_store_error() {
  if (hooks_.store_write_failed) hooks_.store_write_failed();
}

void Scheduler::start() {
  std::lock_guard lock(mutex_);
  if (started_) return;
  started_ = true;
  if (int n = store_.requeue_running(); n > 0)
    log(LogLevel::kInfo, "requeued jobs left running by a previous process; they resume from their checkpoints",
        {{"count", n}});
  dispatcher_ = std::thread([this] { dispatch_loop(); });
}

void Scheduler::wake() {
  cv_.notify_all();
}

bool Scheduler::accepting() const {
  std::lock_guard lock(mutex_);
  return started_ && !stopping_;
}

int Scheduler::running_count() const {
  std::lock_guard lock(mutex_);
  return static_cast<int>(running_.size());
}

bool Scheduler::store_failing() const {
  std::lock_guard lock(mutex_);
  return std::any_of(running_.begin(), running_.end(), [](const auto& entry) { return entry.second->awaiting_store; });
}

void Scheduler::begin_drain() {
  {
    std::lock_guard lock(mutex_);
    if (!started_) return;
    stopping_ = true;
    // A load has no pass to end: it stops now, and the job is requeued.
    for (auto& [id, slot] : running_) slot->control.stop();
  }
  cv_.notify_all();
}

void Scheduler::shutdown(double grace_s) {
  {
    std::lock_guard lock(mutex_);
    if (!started_ || !dispatcher_.joinable()) return;
  }
  begin_drain();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(grace_s);
  {
    std::unique_lock lock(mutex_);
    while (!running_.empty() && std::chrono::steady_clock::now() < deadline) {
      bool all_done = true;
      for (auto& [id, slot] : running_) all_done = all_done && slot->done;
      if (all_done) break;
      cv_.wait_for(lock, std::chrono::milliseconds(20));
    }
    // Out of time: abandon the passes under way; the last checkpoints stay.
    for (auto& [id, slot] : running_) slot->abandon();
  }
  cv_.notify_all();
  if (dispatcher_.joinable()) dispatcher_.join();
}

void Scheduler::reap_finished_locked(std::unique_lock<std::mutex>& lock) {
  for (auto it = running_.begin(); it != running_.end();) {
    if (!it->second->done) {
      ++it;
      continue;
    }
    std::shared_ptr<RenderSlot> slot = it->second;
    it = running_.erase(it);
    lock.unlock();  // the thread has finished its work; joining only waits for it to return
    slot->thread.join();
    lock.lock();
    it = running_.begin();
  }
}

// Renews the lease of each render under way once per renewal period (lease_renewal_period_ms), or poll interval if
// that is shorter. A lease the store refuses is lost: the render
// stops and records nothing (the job ended, was paused or deleted elsewhere, or another daemon took it over after this
// one failed to renew in time). A store that fails leaves the render going: its lease may still be renewed in time.
void Scheduler::renew_leases_locked() {
  const auto now = std::chrono::steady_clock::now();
  for (auto& [id, slot] : running_)
    if (now - slot->renewed_at >= renewal_period()) renew_lease_locked(*slot, "its lease renewal");
}

std::chrono::milliseconds Scheduler::renewal_period() const {
  return std::min(options_.poll_interval, std::chrono::milliseconds(lease_renewal_period_ms(options_.lease.count())));
}

void Scheduler::renew_lease_locked(RenderSlot& slot, const char* noticed_by) {
  // A run recording its end has its outcome fenced by end_run(): the store's own change of state is no loss of lease.
  if (slot.done || slot.lease_lost || slot.ending || slot.settled) return;
  try {
    if (store_.renew_lease(slot.id, slot.epoch, now_ms(), options_.lease.count()))
      slot.renewed_at = std::chrono::steady_clock::now();
    else
      lose_lease_locked(slot, noticed_by);
  } catch (const JobStoreError& e) {
    count_store_error();
    log(LogLevel::kWarn, "cannot renew the lease of a job; the render goes on",
        {{"job", slot.id}, {"error", e.what()}});
  }
}

void Scheduler::job_changed(const std::string& id, bool claimable) {
  {
    std::lock_guard lock(mutex_);
    for (RenderSlot* slot : slots_locked(id)) renew_lease_locked(*slot, "the store's notification");
  }
  if (claimable) cv_.notify_all();
}

void Scheduler::recheck() {
  {
    std::lock_guard lock(mutex_);
    for (auto& [id, slot] : running_) renew_lease_locked(*slot, "a look afresh once notifications were back");
  }
  cv_.notify_all();
}

void Scheduler::lose_lease_locked(RenderSlot& slot, const char* noticed_by) {
  // A render stopped by a client's change knows why its writes are refused: nothing more to stop or say.
  if (slot.lease_lost || slot.settled) return;
  slot.lease_lost = true;
  slot.abandon();
  log(LogLevel::kInfo, "the job was changed or taken over elsewhere; its render here stops and records nothing",
      {{"job", slot.id}, {"epoch", slot.epoch}, {"noticed_by", noticed_by}});
}

void Scheduler::dispatch_loop() {
  std::unique_lock lock(mutex_);
  while (!stopping_) {
    reap_finished_locked(lock);
    while (!stopping_ && claims_held_ == 0 && static_cast<int>(running_.size()) < options_.max_jobs) {
      std::optional<JobRecord> record;
      try {
        record = store_.claim_next(now_ms(), options_.lease.count(), options_.max_running_per_user);
      } catch (const std::exception& e) {
        log(LogLevel::kError, "cannot claim a job", {{"error", e.what()}});
        break;
      }
      if (!record) break;
      auto slot = std::make_shared<RenderSlot>();
      slot->id = record->id;
      slot->unit = record->unit;
      slot->epoch = record->epoch;
      // A slot per job rendered whole, per unit of a split one (units of one job may render here side by side); a
      // run claimed again while the last one here winds down (it was paused and resumed) gets a slot of its own.
      std::string key = slot->unit < 0 ? slot->id : slot->id + "/" + std::to_string(slot->unit);
      if (running_.contains(key)) (key += '@') += std::to_string(slot->epoch);
      running_[key] = slot;
      slot->thread = std::thread([this, slot, rec = std::move(*record)] { run_job(slot, rec); });
    }
    renew_leases_locked();
    cv_.wait_for(lock, running_.empty() ? options_.poll_interval : renewal_period());
  }
  // Shutting down: every render has been told to stop; wait for them to put their jobs back.
  while (!running_.empty()) {
    cv_.wait_for(lock, std::chrono::milliseconds(20));
    reap_finished_locked(lock);
  }
}

// A run's steps: claimed by dispatch_loop(), it renders (render_run: its runner loads, restores and renders, and
// reports each step) and publishes its end (end_interrupted, end_unit, end_job, end_crashed); the merge of a split
// job's units and the failure of a job lost too often are runs of their own. Whatever the end, finish_run() releases
// the slot.
void Scheduler::run_job(const std::shared_ptr<RenderSlot>& slot, const JobRecord& record) {
  // The job's files have their place from here on; writes never make it (JobFiles::prepare), so a render still
  // winding down cannot bring back the files of a job that was deleted meanwhile.
  files_.prepare(record.id);
  notify_state(record.id);
  // A frame of a range is retried on its unit's count of lost runs (work_units.h), a job on its own.
  const bool frames = renders_frames(render_settings_from_text(record.settings));
  if ((frames && record.unit >= 0 ? record.unit_lost_runs : record.lost_runs) > options_.crash_retries) {
    fail_lost_too_often(*slot, record);
  } else if (record.unit >= 0 && record.unit >= record.units) {
    try {
      if (frames)
        finish_frames(*slot, record);
      else
        merge_units(*slot, record);
    } catch (const std::exception& e) {
      record_failure(*slot, std::string(frames ? "cannot finish its frames: " : "cannot merge its units: ") + e.what(),
                     0, false);
    }
  } else {
    render_run(*slot, record);
  }
  finish_run(*slot);
}

// The slot's last step, whatever the run's end: the files of a job deleted meanwhile go; the dispatcher, woken, reaps
// the slot (and may claim what the end made claimable: a split job's merge).
void Scheduler::finish_run(RenderSlot& slot) {
  bool deleted;
  {
    std::lock_guard lock(mutex_);
    deleted = slot.delete_requested;
  }
  if (deleted)
    files_.remove(slot.id);
  else
    notify_state(slot.id);
  {
    std::lock_guard lock(mutex_);
    slot.done = true;
  }
  cv_.notify_all();
}

// One run of a job here: what it renders, and what it has published so far.
struct Scheduler::Run {
  RenderSlot& slot;
  const JobRecord& record;
  RenderSettings settings;  // run_settings(): a unit's narrowed to its range
  OutputPipeline outputs;
  uint32_t samples_counted = 0;  // the samples per pixel counted in SchedulerHooks::samples_rendered
  bool ended = false;
  std::optional<int64_t> frame;  // of a frame range: the frame under way, which the log lines of its passes name

  // "frame 12: " while a frame of a range renders, "unit 3: " for a unit of a split job; empty otherwise.
  std::string who() const {
    if (frame) return "frame " + std::to_string(*frame) + ": ";
    return is_unit() ? printf_string("unit %d: ", record.unit + 1) : std::string();
  }

  Run(RenderSlot& s, const JobRecord& r, const RenderRequest& request)
      : slot(s), record(r), settings(run_settings(request)), outputs(settings, output_spec_from_text(r.outputs)) {}
  const std::string& id() const { return record.id; }
  bool is_unit() const { return record.unit >= 0; }
};

// The render's reports, on the run's thread, to the scheduler's steps.
class Scheduler::RunReport final : public RunListener {
 public:
  RunReport(Scheduler& scheduler, Run& run) : scheduler_(scheduler), run_(run) {}

  void loaded(const std::vector<std::string>& warnings, double load_s) override {
    scheduler_.log_.add(run_.id(), printf_string("scene loaded in %.3f s", load_s));
    scheduler_.record_warnings(run_.id(), warnings);
  }
  void resumed(const std::optional<RenderProgress>& restored, bool unusable) override {
    scheduler_.resumed(run_, restored, unusable);
    run_.samples_counted = restored ? restored->samples_done : 0;
    scheduler_.log_start(run_);
  }
  void pass(const RenderProgress& progress, const std::string& write_error) override {
    scheduler_.publish_pass(run_, progress, write_error);
  }
  void frame(int64_t frame, const std::string& event) override {
    run_.frame = frame;
    scheduler_.log_.add(run_.id(), run_.who() + event);
  }
  void ended(const RunEnd& end) override {
    run_.ended = true;
    scheduler_.end_run_reported(run_, end);
  }

 private:
  Scheduler& scheduler_;
  Run& run_;
};

void Scheduler::render_run(RenderSlot& slot, const JobRecord& record) {
  std::optional<Run> run;
  try {
    const RenderRequest request = render_request(record, slot.epoch);
    run.emplace(slot, record, request);
    log_.add(record.id, "loading the scene");
    RunReport report(*this, *run);
    runner_->run(request, slot.control, report);
  } catch (const std::exception& e) {
    // The stored settings do not read, or a step of the scheduler failed where the runner could not report it.
    if (!run || !run->ended) record_failure(slot, e.what(), 0, false);
  }
}

void Scheduler::end_run_reported(Run& run, const RunEnd& end) {
  RenderSlot& slot = run.slot;
  switch (end.outcome) {
    case RunOutcome::kInterrupted:
      end_interrupted(slot, run.record, end.progress.samples_done);
      return;
    case RunOutcome::kRendered:
      if (!still_ours_before_outputs(slot)) {
        if (!run.is_unit()) results_.settle_staged(run.id(), slot.epoch, false);
        end_interrupted(slot, run.record, end.progress.samples_done);
      } else if (run.is_unit()) {
        end_unit(run, end);
      } else {
        end_job(run, end);
      }
      return;
    case RunOutcome::kFailed:
      record_failure(slot, end.error, end.progress.elapsed_s, end.input_refused);
      return;
    case RunOutcome::kCrashed: {
      // A frame range's run died rendering a frame: its error names the frame.
      RunEnd named = end;
      if (run.frame) named.error = run.who() + end.error;
      end_crashed(slot, run.record, named);
      return;
    }
  }
}

void Scheduler::record_warnings(const std::string& id, const std::vector<std::string>& warnings) {
  for (const std::string& w : warnings) log_.add(id, "warning: " + w);
  if (warnings.empty()) return;
  try {
    store_.set_warnings(id, json(warnings).dump());
  } catch (const JobStoreError& e) {
    // Only the job's status misses them: not worth the render.
    count_store_error();
    log(LogLevel::kWarn, "cannot record the warnings of a job", {{"job", id}, {"error", e.what()}});
  }
}

void Scheduler::log_start(const Run& run) {
  const RenderSettings& s = run.settings;
  const JobRecord& record = run.record;
  log(LogLevel::kInfo, "job started",
      {{"job", record.id}, {"samples_done", run.samples_counted}, {"unit", record.unit}, {"where", runner_->where()}});
  if (run.is_unit() && renders_frames(s))
    log_.add(record.id,
             printf_string("unit %d of %d: rendering %s of %dx%d, %u spp, integrator %s, on %d threads "
                           "(epoch %lld, %s)",
                           record.unit + 1, record.units, describe_frames(unit_frames(s, record.unit)).c_str(), s.width,
                           s.height, static_cast<unsigned>(s.spp), s.integrator.name.c_str(), runner_->threads(),
                           static_cast<long long>(run.slot.epoch), runner_->where()));
  else if (run.is_unit())
    log_.add(record.id,
             printf_string("unit %d of %d: rendering samples %u..%u of %dx%d, integrator %s, on %d threads (epoch "
                           "%lld, %s)",
                           record.unit + 1, record.units, static_cast<unsigned>(s.first_sample),
                           static_cast<unsigned>(s.first_sample + s.spp), s.width, s.height, s.integrator.name.c_str(),
                           runner_->threads(), static_cast<long long>(run.slot.epoch), runner_->where()));
  else if (renders_frames(s))
    log_.add(
        record.id,
        printf_string("rendering frames %lld..%lld step %lld (%llu frames) of %dx%d, %u spp, integrator "
                      "%s, on %d threads %s",
                      static_cast<long long>(s.frames->start), static_cast<long long>(s.frames->end),
                      static_cast<long long>(s.frames->step), static_cast<unsigned long long>(frame_count(*s.frames)),
                      s.width, s.height, static_cast<unsigned>(s.spp), s.integrator.name.c_str(), runner_->threads(),
                      runner_->where()));
  else
    log_.add(record.id, printf_string("rendering %dx%d, %u spp, integrator %s, on %d threads %s", s.width, s.height,
                                      static_cast<unsigned>(s.spp), s.integrator.name.c_str(), runner_->threads(),
                                      runner_->where()));
}

void Scheduler::publish_pass(Run& run, const RenderProgress& p, const std::string& write_error) {
  const std::string& id = run.id();
  const JobProgress jp = to_job_progress(p);
  if (hooks_.samples_rendered) {
    const uint64_t pixels = static_cast<uint64_t>(run.settings.width) * static_cast<uint64_t>(run.settings.height);
    hooks_.samples_rendered(pixels * (p.samples_done - run.samples_counted));
  }
  run.samples_counted = p.samples_done;
  try {
    // Files first, then the news: once the progress says N samples, a crash resumes from N and the preview of that
    // pass can be fetched. A unit's checkpoint is named by its run's epoch: the store's update below makes it the
    // unit's. A pass whose files could not be written (a full disk) is not worth the render: the last good
    // checkpoint stays, and the next pass writes both again.
    if (!write_error.empty()) throw std::runtime_error(write_error);
    log_.add(id, printf_string("%spass %u: %u/%u spp, %.2f s, %.3g samples/s", run.who().c_str(),
                               static_cast<unsigned>(p.pass), static_cast<unsigned>(p.samples_done),
                               static_cast<unsigned>(p.samples_total), p.elapsed_s, p.samples_per_s));
    // The store, then the status: what a client reads of the job while it renders is never ahead of what the store
    // holds (a cancel or pause made on it keeps the image of the passes a client saw).
    if (!store_.update_progress(id, run.slot.epoch, jp)) {
      std::lock_guard lock(mutex_);
      lose_lease_locked(run.slot, "its progress refused");
      return;
    }
    {
      std::lock_guard lock(mutex_);
      run.slot.progress = jp;
    }
    if (!run.is_unit()) {
      if (hooks_.progress) hooks_.progress(id, jp);
      if (hooks_.preview) hooks_.preview(id, p.pass);
    } else if (hooks_.progress) {
      // The job's progress over every unit and node, as the store sums it.
      if (auto now = store_.get(id)) hooks_.progress(id, now->progress);
    }
  } catch (const std::exception& e) {
    {
      std::lock_guard lock(mutex_);
      run.slot.progress = jp;
    }
    if (dynamic_cast<const JobStoreError*>(&e)) count_store_error();
    // A missed checkpoint or preview (a full disk) is not worth the render: the last good checkpoint stays, and the
    // next pass writes both again.
    log(LogLevel::kWarn, "cannot publish progress; retried after the next pass", {{"job", id}, {"error", e.what()}});
  }
}

// Before the outputs, which land where other daemons may read them (a shared data directory): is the run still this
// daemon's? A store that fails here changes nothing: the end is recorded, fenced, and retried as ever. False for a
// job deleted meanwhile too.
bool Scheduler::still_ours_before_outputs(RenderSlot& slot) {
  {
    std::lock_guard lock(mutex_);
    if (slot.delete_requested) return false;
  }
  try {
    if (!store_.renew_lease(slot.id, slot.epoch, now_ms(), options_.lease.count())) {
      std::lock_guard lock(mutex_);
      lose_lease_locked(slot, "its lease checked before its outputs");
      return false;
    }
  } catch (const JobStoreError&) {
    count_store_error();
  }
  return true;
}

// A render (or a load) that stopped before its end: the job was deleted, cancelled or paused by a client (the store
// has the change already), changed or taken over elsewhere, or (the daemon stopping) goes back to the queue, to
// resume from its last checkpoint. Only that last end is the run's to record.
void Scheduler::end_interrupted(RenderSlot& slot, const JobRecord& record, uint32_t samples_done) {
  bool deleted, lease_lost;
  std::optional<StopSignal> settled;
  {
    std::lock_guard lock(mutex_);
    deleted = slot.delete_requested;
    lease_lost = slot.lease_lost;
    settled = slot.settled;
  }
  if (deleted)
    log(LogLevel::kInfo, "job deleted while rendering", {{"job", record.id}});
  else if (settled) {
    // A pass's checkpoint written while the service cancelled would outlive the job's own removal of it: the render,
    // the last writer, removes it again once it has stopped.
    if (*settled == StopSignal::kCancel && record.unit < 0) files_.remove(record.id, JobFile::kCheckpoint);
    log_settled(record, *settled, samples_done);
  } else if (lease_lost)
    end_taken_away(record.id, samples_done);
  else
    end_stopping(slot, record.id, samples_done);
}

void Scheduler::log_settled(const JobRecord& record, StopSignal signal, uint32_t samples_done) {
  const auto spp = static_cast<unsigned>(samples_done);
  const bool cancelled = signal == StopSignal::kCancel;
  if (record.unit >= 0)
    log_.add(record.id, printf_string("unit %d stopped at %u spp: the job was %s by a client", record.unit + 1, spp,
                                      cancelled ? "cancelled" : "paused"));
  else if (cancelled)
    log_.add(record.id, printf_string("cancelled by a client at %u spp", spp));
  else
    log_.add(record.id, printf_string("paused by a client at %u spp; its checkpoint is kept", spp));
  log(LogLevel::kInfo, cancelled ? "render stopped: its job was cancelled" : "render stopped: its job was paused",
      {{"job", record.id}, {"unit", record.unit}, {"samples_done", samples_done}});
}

void Scheduler::end_taken_away(const std::string& id, uint32_t samples_done) {
  // Whoever holds the job now owns its end. Its files go only if the job is gone.
  log_.add(id, printf_string("stopped at %u spp: the job was changed or taken over elsewhere",
                             static_cast<unsigned>(samples_done)));
  log(LogLevel::kInfo, "render stopped: the job was changed or taken over elsewhere",
      {{"job", id}, {"samples_done", samples_done}});
  try {
    if (!store_.get(id)) files_.remove(id);
  } catch (const JobStoreError& e) {
    count_store_error();
    log(LogLevel::kWarn, "cannot tell whether a job taken away was deleted; its files stay",
        {{"job", id}, {"error", e.what()}});
  }
}

// The daemon is stopping (or an unexpected stop): back to the queue; the last checkpoint resumes it. The end goes to
// the store through record_end(): retried while the store fails; when the daemon stops first, the job stays running
// in the store, with its checkpoint, for the next start to resume.
void Scheduler::end_stopping(RenderSlot& slot, const std::string& id, uint32_t samples_done) {
  log_.add(id, printf_string("the daemon is stopping: back in the queue at %u spp, to resume from its checkpoint",
                             static_cast<unsigned>(samples_done)));
  if (record_end(slot, [&] { return store_.end_run(id, slot.epoch, JobState::kQueued, now_ms()); }))
    log(LogLevel::kInfo, "job put back in the queue; it resumes from its checkpoint",
        {{"job", id}, {"samples_done", samples_done}});
}

void Scheduler::end_unit(Run& run, const RunEnd& end) {
  const std::string& id = run.id();
  const JobRecord& record = run.record;
  const RenderSettings& s = run.settings;
  const RenderProgress& p = end.progress;
  const bool frames = renders_frames(s);
  if (frames)
    log_.add(id, printf_string("unit %d of %d done: %s in %.2f s", record.unit + 1, record.units,
                               describe_frames(unit_frames(s, record.unit)).c_str(), p.elapsed_s));
  else
    log_.add(id, printf_string("unit %d of %d done: samples %u..%u in %.2f s", record.unit + 1, record.units,
                               static_cast<unsigned>(s.first_sample), static_cast<unsigned>(s.first_sample + s.spp),
                               p.elapsed_s));
  if (!record_end(run.slot, [&] { return store_.end_run(id, run.slot.epoch, JobState::kSucceeded, now_ms()); })) return;
  log(LogLevel::kInfo, "unit done",
      {{"job", id}, {"unit", record.unit}, {"epoch", run.slot.epoch}, {"elapsed_s", p.elapsed_s}});
  if (frames) return;  // its frames' preview was written with them
  // The preview refines as units finish: the merge of those done so far, when 1, 2, 4, 8, ... are done, so that the
  // films all previews read stay under twice those of the job's merge (a merge reads every done unit's film; after
  // each unit, a job of n units would read n^2 / 2). Best effort.
  try {
    const std::vector<UnitRecord> units = store_.units(id);
    const auto done =
        static_cast<unsigned>(std::count_if(units.begin(), units.end(), [](const UnitRecord& u) { return u.done; }));
    std::optional<Film> film;
    if (std::has_single_bit(done) && done < units.size())
      film = results_.merge_unit_films(record, s.width, s.height, false);
    if (film) {
      files_.write(id, JobFile::kPreviewPng, run.outputs.preview_png(*film));
      if (hooks_.preview) hooks_.preview(id, film->samples());
    }
  } catch (const std::exception& e) {
    log(LogLevel::kWarn, "cannot write the preview of a split job", {{"job", id}, {"error", e.what()}});
  }
}

void Scheduler::end_job(Run& run, const RunEnd& end) {
  const std::string& id = run.id();
  // The render staged the outputs (a file that cannot be written, a full disk, failed the job, as it should); they
  // are published once the store takes the end (publish_outputs()).
  const std::string& written = end.written;
  const StopReason reason = end.reason;
  JobProgress final_progress = to_job_progress(end.progress);
  final_progress.eta_s = 0;
  log_.add(id, printf_string("succeeded: %s after %.2f s, %u spp in %u passes; wrote%s", stop_explained(reason).c_str(),
                             final_progress.elapsed_s, static_cast<unsigned>(final_progress.samples_done),
                             static_cast<unsigned>(final_progress.passes), written.c_str()));
  const bool recorded =
      record_terminal(run.slot, JobState::kSucceeded, final_progress.elapsed_s, stop_reason_name(reason), "",
                      [&] { store_.update_progress(id, run.slot.epoch, final_progress); });
  publish_outputs(run.slot, recorded);
  if (recorded)
    log(LogLevel::kInfo, "job succeeded",
        {{"job", id},
         {"elapsed_s", final_progress.elapsed_s},
         {"samples_per_s", final_progress.samples_per_s},
         {"stop_reason", stop_reason_name(reason)}});
}

// A failing store is no fault of the job: the render's outcome stands and is written again, after 100 ms doubling up
// to 5 s (SchedulerOptions), until the store takes it; meanwhile the job's slot stays taken (counting against
// max_jobs, rightly: no other job could record its end either). Logged at the first failure, then at most every 10 s.
// False when the daemon stops first: the job is then left running in the store, and requeue_running() at the next
// start puts it back in the queue, to resume from its checkpoint (kept until its end is recorded). False too when
// `write` returns false: the store's state machine refused the move (the job was deleted, or changed elsewhere), and
// nothing may be done as if it had been made. Anything else `write` throws goes through.
bool Scheduler::record_end(RenderSlot& slot, const std::function<bool()>& write) {
  using Clock = std::chrono::steady_clock;
  constexpr auto kLogInterval = std::chrono::seconds(10);
  std::chrono::milliseconds wait = options_.store_retry_first;
  int failures = 0;
  Clock::time_point logged_at;
  bool taken = false;
  {
    std::lock_guard lock(mutex_);
    slot.ending = true;
  }
  for (;;) {
    try {
      taken = write();
      break;
    } catch (const JobStoreError& e) {
      count_store_error();
      if (++failures == 1 || Clock::now() - logged_at >= kLogInterval) {
        logged_at = Clock::now();
        log(LogLevel::kError, "cannot record the end of a job: the job store failed; retrying",
            {{"job", slot.id}, {"error", e.what()}, {"failures", failures}});
      }
    }
    std::unique_lock lock(mutex_);
    slot.awaiting_store = true;
    if (cv_.wait_for(lock, wait, [this] { return stopping_; })) {
      slot.awaiting_store = false;
      log(LogLevel::kWarn,
          "stopping with the end of a job unrecorded: it stays running in the store, and the next start resumes it "
          "from its checkpoint",
          {{"job", slot.id}, {"failures", failures}});
      return false;
    }
    wait = std::min(wait * 2, options_.store_retry_max);
  }
  if (failures > 0) {
    {
      std::lock_guard lock(mutex_);
      slot.awaiting_store = false;
    }
    log(LogLevel::kInfo, "the job store recovered; the end of the job is written",
        {{"job", slot.id}, {"failures", failures}});
  }
  if (!taken)
    log(LogLevel::kWarn, "the job store refused the end of a job: it was deleted or changed meanwhile",
        {{"job", slot.id}});
  return taken;
}

// Records that a job ended in `to` (succeeded, failed or cancelled) as record_end() does, its render time counted in
// the same step (SchedulerHooks::job_ended); `before` runs first in every attempt (the final progress). Its
// checkpoint goes once the end is recorded. False when it was not.
bool Scheduler::record_terminal(RenderSlot& slot, JobState to, double render_s, const std::string& stop_reason,
                                const std::string& error, const std::function<void()>& before) {
  const bool recorded = record_end(slot, [&] {
    if (before) before();
    auto record = [&] { return store_.end_run(slot.id, slot.epoch, to, now_ms(), stop_reason, error); };
    return hooks_.job_ended ? hooks_.job_ended(render_s, record) : record();
  });
  if (recorded) files_.remove(slot.id, JobFile::kCheckpoint);
  return recorded;
}

// Logs a job that failed (its scene, its outputs) and records it as record_terminal() does, with the stop reason
// kInputRefused when its input is at fault; false when it was not recorded.
// A run resumes from the job's checkpoint (a unit's: the one the store names as its own, of the last run that
// recorded one).
void Scheduler::resumed(Run& run, const std::optional<RenderProgress>& restored, bool unusable) {
  RenderSlot& slot = run.slot;
  const JobRecord& record = run.record;
  const std::string& id = record.id;
  // A run taken over from a node that stopped renewing its lease says so, whatever it resumes from: the wait for the
  // lease to expire is otherwise invisible in the log.
  const std::string who = record.unit >= 0 ? printf_string("unit %d: ", record.unit + 1) : std::string();
  const std::string takeover =
      record.taken_over_from.empty()
          ? std::string()
          : who + "node " + record.taken_over_from + " stopped renewing its lease; taken over by this node, ";
  if (unusable) {
    log(LogLevel::kWarn, "checkpoint unusable; the render starts over", {{"job", id}});
    log_.add(id, "warning: its checkpoint is unusable (damaged, or of other settings); the render starts over");
  }
  if (!restored) {
    if (!takeover.empty()) log_.add(id, takeover + "starting over (it left no checkpoint)");
    return;
  }
  log(LogLevel::kInfo, "job resumed from its checkpoint",
      {{"job", id}, {"samples_done", restored->samples_done}, {"passes", restored->pass}});
  if (renders_frames(run.settings))
    log_.add(id, printf_string("%sresuming: %u of its %zu frames were rendered by earlier runs and are kept",
                               takeover.c_str(), static_cast<unsigned>(restored->samples_done / run.settings.spp),
                               record.unit >= 0 ? unit_frames(run.settings, record.unit).size()
                                                : static_cast<size_t>(frame_count(*run.settings.frames))));
  else
    log_.add(id, printf_string("%sresuming from its checkpoint at %u spp (%u passes)",
                               takeover.empty() ? "" : takeover.c_str(), static_cast<unsigned>(restored->samples_done),
                               static_cast<unsigned>(restored->pass)));
  const JobProgress progress = to_job_progress(*restored);
  {
    std::lock_guard lock(mutex_);
    slot.progress = progress;
  }
  try {
    if (!store_.update_progress(id, slot.epoch, progress)) return;  // the run is no longer ours: its render finds out
  } catch (const JobStoreError& e) {
    count_store_error();
    log(LogLevel::kWarn, "cannot record a resumed job's progress; the next pass does",
        {{"job", id}, {"error", e.what()}});
    return;
  }
  if (!hooks_.progress) return;
  if (record.unit < 0) {
    hooks_.progress(id, progress);
  } else if (auto now = store_.get(id)) {  // the job's progress over every unit and node, as the store sums it
    hooks_.progress(id, now->progress);
  }
}

void Scheduler::end_crashed(RenderSlot& slot, const JobRecord& record, const RunEnd& end) {
  const std::string& id = record.id;
  bool changed;
  {
    std::lock_guard lock(mutex_);
    changed = slot.delete_requested || slot.settled || slot.lease_lost;
  }
  log(LogLevel::kError, "a render worker died", {{"job", id}, {"unit", record.unit}, {"error", end.error}});
  // A job deleted, cancelled, paused or taken over meanwhile is no longer this run's to record.
  if (changed) {
    end_interrupted(slot, record, end.progress.samples_done);
    return;
  }
  // A unit of a frame range counts its own lost runs; any other run, its job's.
  const bool frame_unit = record.unit >= 0 && renders_frames(render_settings_from_text(record.settings));
  const int lost = (frame_unit ? record.unit_lost_runs : record.lost_runs) + 1;
  if (lost > options_.crash_retries) {
    record_failure(slot,
                   end.error + printf_string(" (%d runs of this %s were lost, more than the %d retries allowed: "
                                             "--crash-retries)",
                                             lost, frame_unit ? "unit" : "job", options_.crash_retries),
                   end.progress.elapsed_s, true);
    return;
  }
  log_.add(id, printf_string("%s%s; rendered again from its last checkpoint (retry %d of %d)",
                             record.unit >= 0 ? printf_string("unit %d: ", record.unit + 1).c_str() : "",
                             end.error.c_str(), lost, options_.crash_retries));
  // The run is given up as lost: its lease ends now, so that the next claim, on this node or another, takes the job
  // over from its last checkpoint and counts a lost run (JobStore::claim_next), as it does for a node that died. A
  // store that fails here leaves the lease to run out by itself.
  try {
    store_.renew_lease(id, slot.epoch, now_ms(), -1);
  } catch (const JobStoreError& e) {
    count_store_error();
    log(LogLevel::kWarn, "cannot end the lease of a crashed run; it runs out by itself",
        {{"job", id}, {"error", e.what()}});
  }
}

void Scheduler::fail_lost_too_often(RenderSlot& slot, const JobRecord& record) {
  const RenderSettings settings = render_settings_from_text(record.settings);
  if (record.unit >= 0 && renders_frames(settings)) {
    record_failure(slot,
                   printf_string("%s: the renderer stopped %d times while rendering it (its process crashed or was "
                                 "killed, or its node stopped), more than the %d retries allowed (--crash-retries)",
                                 describe_frames(unit_frames(settings, record.unit)).c_str(), record.unit_lost_runs,
                                 options_.crash_retries),
                   0, true);
    return;
  }
  record_failure(slot,
                 printf_string("the renderer stopped %d times while rendering this job (its process crashed or was "
                               "killed: the scene may crash the renderer), more than the %d retries allowed "
                               "(--crash-retries)",
                               record.lost_runs, options_.crash_retries),
                 0, true);
}

bool Scheduler::record_failure(RenderSlot& slot, const std::string& message, double render_s, bool input_refused) {
  log(LogLevel::kError, "job failed", {{"job", slot.id}, {"error", message}, {"input_refused", input_refused}});
  log_.add(slot.id,
           "failed: " + message + (input_refused ? " (its input is at fault: it would fail the same way again)" : ""));
  try {
    return record_terminal(slot, JobState::kFailed, render_s, input_refused ? std::string(kInputRefused) : "", message);
  } catch (const std::exception& e) {
    // Not a store failure (those are retried): nothing more can be done for this run.
    log(LogLevel::kError, "cannot record a failed job", {{"job", slot.id}, {"error", e.what()}});
    return false;
  }
}

// A run's outputs are fenced by its end. They are staged under names of its epoch (JobFiles::stage), its end is
// recorded (end_run, refused unless the job is still running under that epoch), and only then are they renamed to
// the names clients read. So a cancel that commits between the run's last lease check and its end keeps the partial
// results its canceller wrote: the refused run's full image is removed, never published. An end whose outcome is not
// known (the store failed after taking it, and refused the retry) is read back: the run's outputs are published when
// the job succeeded under its epoch. A crash between the end and the renames leaves the staged files, which
// JobService::result() publishes when a client asks for a succeeded job's missing result (the job's epoch is the
// run's), so a succeeded job is never left without its outputs.
void Scheduler::publish_outputs(RenderSlot& slot, bool recorded) {
  bool publish = recorded;
  if (!recorded) {
    try {
      const auto now = store_.get(slot.id);
      if (now && now->state == JobState::kSucceeded && now->epoch == slot.epoch)
        publish = true;
      else if (now)
        publish = false;
      else
        return;  // deleted: its files go with it
    } catch (const JobStoreError& e) {
      // Unknown: the staged files stay, published on demand if the run's end was taken (JobService::result()).
      count_store_error();
      log(LogLevel::kWarn, "cannot tell whether the end of a job was taken; its outputs stay staged",
          {{"job", slot.id}, {"error", e.what()}});
      return;
    }
  }
  if (!publish)
    log_.add(slot.id, "its outputs are not published: the job was changed elsewhere before its end was recorded");
  results_.settle_staged(slot.id, slot.epoch, publish);
}

void Scheduler::merge_units(RenderSlot& slot, const JobRecord& record) {
  const std::string& id = record.id;
  const RenderSettings settings = render_settings_from_text(record.settings);
  const auto start = std::chrono::steady_clock::now();
  std::optional<Film> film = results_.merge_unit_films(record, settings.width, settings.height, false);
  if (!film || film->samples() != record.progress.samples_total)
    throw std::runtime_error(printf_string("its units' films hold %u of its %u samples per pixel",
                                           static_cast<unsigned>(film ? film->samples() : 0),
                                           static_cast<unsigned>(record.progress.samples_total)));
  // Outputs land where every node reads them: is the merge still this node's? (A merge taken over writes the same
  // bits: the films it reads are the units' authoritative ones, and a done unit is never rendered again.)
  if (!store_.renew_lease(id, slot.epoch, now_ms(), options_.lease.count())) {
    std::lock_guard lock(mutex_);
    lose_lease_locked(slot, "its lease checked before the merge");
    return;
  }
  const OutputPipeline outputs(settings, output_spec_from_text(record.outputs));
  const Image image = outputs.image(*film);
  const std::string written = stage_outputs(files_, id, outputs, image, slot.epoch);
  files_.write(id, JobFile::kPreviewPng, outputs.preview_png(image));
  const double merge_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  log_.add(id, printf_string("succeeded: its %d units merged in %.3f s, %u spp; wrote%s", record.units, merge_s,
                             static_cast<unsigned>(film->samples()), written.c_str()));
  const bool recorded = record_terminal(slot, JobState::kSucceeded, merge_s, stop_reason_name(StopReason::kSamples));
  publish_outputs(slot, recorded);
  if (recorded) {
    files_.remove_units(id);
    log(LogLevel::kInfo, "job succeeded", {{"job", id}, {"units", record.units}, {"merge_s", merge_s}});
  }
}

void Scheduler::finish_frames(RenderSlot& slot, const JobRecord& record) {
  const std::string& id = record.id;
  const RenderSettings settings = render_settings_from_text(record.settings);
  const OutputSpec spec = output_spec_from_text(record.outputs);
  const int padding = frame_padding(*settings.frames);
  for (int64_t frame : frame_numbers(*settings.frames))
    if (!files_.open_frame(id, frame_done_file(spec), frame, padding))
      throw std::runtime_error("frame " + std::to_string(frame) + "'s " + job_file_name(frame_done_file(spec)) +
                               " is missing from the data directory");
  log_.add(id, printf_string("succeeded: its %llu frames are done, in %d units",
                             static_cast<unsigned long long>(frame_count(*settings.frames)), record.units));
  if (record_terminal(slot, JobState::kSucceeded, 0, stop_reason_name(StopReason::kSamples)))
    log(LogLevel::kInfo, "job succeeded", {{"job", id}, {"units", record.units}});
}

std::vector<Scheduler::RenderSlot*> Scheduler::slots_locked(const std::string& id) const {
  std::vector<RenderSlot*> out;
  for (const auto& [key, slot] : running_)
    if (slot->id == id) out.push_back(slot.get());
  return out;
}

std::vector<Scheduler::RenderSlot*> Scheduler::rendering_locked(const std::string& id) const {
  std::vector<RenderSlot*> out = slots_locked(id);
  std::erase_if(out, [](RenderSlot* slot) { return slot->done; });
  return out;
}

std::optional<JobProgress> Scheduler::live_progress(const std::string& id) const {
  std::lock_guard lock(mutex_);
  auto it = running_.find(id);  // a job rendered whole; a split job's progress is its units' in the store
  if (it == running_.end()) return std::nullopt;
  return it->second->progress;
}

int Scheduler::stop(const std::string& id, StopSignal signal) {
  std::lock_guard lock(mutex_);
  const std::vector<RenderSlot*> slots = rendering_locked(id);
  for (RenderSlot* slot : slots) {
    slot->signal(signal);
  }
  return static_cast<int>(slots.size());
}

bool Scheduler::remove(const std::string& id, std::optional<int64_t> only_finished_before_ms) {
  std::unique_lock lock(mutex_);
  std::vector<std::shared_ptr<RenderSlot>> slots;
  for (const auto& [key, slot] : running_)
    if (slot->id == id) slots.push_back(slot);
  if (slots.empty()) {
    if (!store_.remove(id, only_finished_before_ms)) return false;
    files_.remove(id);
    log(LogLevel::kInfo, "job deleted", {{"job", id}});
    return true;
  }
  if (only_finished_before_ms) return false;  // still (or again) rendering, or not yet reaped: not expired
  // The store first: one that fails (JobStoreError) leaves the render going and the job whole. The other way round,
  // the render would stop and its files go while the store kept the job running, with no render behind it.
  store_.remove(id);
  const bool winding_down =
      std::all_of(slots.begin(), slots.end(), [](const auto& s) { return s->settled || s->done; });
  for (const auto& slot : slots) {
    slot->delete_requested = true;
    slot->abandon();
  }
  if (!winding_down) return true;  // the render's thread removes the files once it has stopped writing them
  // Only renders winding down after a client's change (the job is cancelled or paused in the store), which the
  // delete ends within a tile's time: waited for, so that the files are gone when the delete returns, as they are for
  // a job no render holds.
  cv_.wait(lock, [&] { return std::all_of(slots.begin(), slots.end(), [](const auto& s) { return s->done; }); });
  files_.remove(id);
  log(LogLevel::kInfo, "job deleted", {{"job", id}});
  return true;
}

}  // namespace tessera::server
