#include "server/scheduler.h"

#include <nlohmann/json.hpp>

#include "renderer/image_io.h"
#include "renderer/job.h"
#include "renderer/scene_error.h"
#include "renderer/session.h"
#include "server/log.h"
#include "server/time_format.h"

namespace tessera::server {

using nlohmann::json;

// One job rendering here. Guarded by the scheduler's mutex, except `thread`, which only the dispatcher touches.
class Scheduler::RenderSlot {
 public:
  std::string id;
  RenderSession* session = nullptr;  // set while the render runs
  bool cancel_requested = false;     // by a client: the job ends cancelled
  bool delete_requested = false;     // by a client: the job is gone, its files go when the render stops
  std::optional<JobProgress> progress;
  bool done = false;
  std::thread thread;
};

namespace {

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
    : store_(store), files_(files), pool_(pool), options_(options) {}

Scheduler::~Scheduler() {
  shutdown();
}

void Scheduler::start() {
  std::lock_guard lock(mutex_);
  if (started_) return;
  started_ = true;
  if (int n = store_.requeue_running(); n > 0)
    log(LogLevel::kInfo, "requeued jobs left running by a previous process", {{"count", n}});
  dispatcher_ = std::thread([this] { dispatch_loop(); });
}

void Scheduler::wake() {
  cv_.notify_all();
}

bool Scheduler::accepting() const {
  std::lock_guard lock(mutex_);
  return started_ && !stopping_;
}

void Scheduler::shutdown() {
  {
    std::lock_guard lock(mutex_);
    if (!started_ || stopping_) return;
    stopping_ = true;
    for (auto& [id, slot] : running_)
      if (slot->session) slot->session->cancel();
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

void Scheduler::dispatch_loop() {
  std::unique_lock lock(mutex_);
  while (!stopping_) {
    reap_finished_locked(lock);
    while (!stopping_ && static_cast<int>(running_.size()) < options_.max_jobs) {
      std::optional<JobRecord> record;
      try {
        record = store_.claim_next(now_ms());
      } catch (const std::exception& e) {
        log(LogLevel::kError, "cannot claim a job", {{"error", e.what()}});
        break;
      }
      if (!record) break;
      auto slot = std::make_shared<RenderSlot>();
      slot->id = record->id;
      running_[slot->id] = slot;
      slot->thread = std::thread([this, slot, rec = std::move(*record)] { run_job(slot, rec); });
    }
    cv_.wait_for(lock, options_.poll_interval);
  }
  // Shutting down: every render has been told to cancel; wait for them to put their jobs back.
  while (!running_.empty()) {
    cv_.wait_for(lock, std::chrono::milliseconds(50));
    reap_finished_locked(lock);
  }
}

void Scheduler::run_job(const std::shared_ptr<RenderSlot>& slot, const JobRecord& record) {
  const std::string& id = record.id;
  log(LogLevel::kInfo, "job started", {{"job", id}});
  auto detach = [&] {
    std::lock_guard lock(mutex_);
    slot->session = nullptr;
  };
  try {
    const json doc = json::parse(record.document);
    JobLoadOptions options;
    options.limits = options_.limits;
    const RenderJob job = load_job(doc, options);
    RenderSession session(job.scene, job.settings, pool_);
    {
      std::lock_guard lock(mutex_);
      slot->session = &session;
      if (slot->cancel_requested || slot->delete_requested || stopping_) session.cancel();
    }
    const StopReason reason = session.run([&](const RenderProgress& p, const Film& film) {
      const JobProgress jp = to_job_progress(p);
      {
        std::lock_guard lock(mutex_);
        slot->progress = jp;
      }
      try {
        store_.update_progress(id, jp);
        files_.write(id, JobFile::kPreviewPng, [&] {
          std::vector<uint8_t> png = encode_png(film.resolve(), film.width(), film.height(), job.settings.display);
          return std::string(png.begin(), png.end());
        }());
      } catch (const std::exception& e) {
        // A missed preview or progress row is not worth the render.
        log(LogLevel::kWarn, "cannot publish progress", {{"job", id}, {"error", e.what()}});
      }
    });
    detach();

    bool cancelled_by_client, deleted, stopping;
    {
      std::lock_guard lock(mutex_);
      cancelled_by_client = slot->cancel_requested;
      deleted = slot->delete_requested;
      stopping = stopping_;
    }
    if (deleted) {
      log(LogLevel::kInfo, "job deleted while rendering", {{"job", id}});
    } else if (reason == StopReason::kCancelled && stopping && !cancelled_by_client) {
      store_.transition(id, JobState::kQueued, now_ms());
      log(LogLevel::kInfo, "job put back in the queue for the next start", {{"job", id}});
    } else if (reason == StopReason::kCancelled) {
      store_.transition(id, JobState::kCancelled, now_ms(), stop_reason_name(reason));
      log(LogLevel::kInfo, "job cancelled", {{"job", id}});
    } else {
      const Film& film = session.film();
      const std::vector<float> rgb = film.resolve();
      if (job.want_png) {
        std::vector<uint8_t> png = encode_png(rgb, film.width(), film.height(), job.settings.display);
        files_.write(id, JobFile::kResultPng, std::string_view(reinterpret_cast<const char*>(png.data()), png.size()));
      }
      if (job.want_exr) {
        files_.write_with(id, JobFile::kResultExr, [&](const std::string& temp) {
          write_exr(temp, rgb, film.width(), film.height(), job.settings.exr_half);
        });
      }
      JobProgress final_progress = to_job_progress(session.progress());
      final_progress.eta_s = 0;
      store_.update_progress(id, final_progress);
      store_.transition(id, JobState::kSucceeded, now_ms(), stop_reason_name(reason));
      log(LogLevel::kInfo, "job succeeded",
          {{"job", id},
           {"elapsed_s", final_progress.elapsed_s},
           {"samples_per_s", final_progress.samples_per_s},
           {"stop_reason", stop_reason_name(reason)}});
    }
  } catch (const std::exception& e) {
    detach();
    std::string message = e.what();
    if (const auto* se = dynamic_cast<const SceneError*>(&e); se && !se->pointer().empty())
      message = se->pointer() + ": " + message;
    try {
      store_.transition(id, JobState::kFailed, now_ms(), "", message);
    } catch (const std::exception& e2) {
      log(LogLevel::kError, "cannot record a failed job", {{"job", id}, {"error", e2.what()}});
    }
    log(LogLevel::kError, "job failed", {{"job", id}, {"error", message}});
  } catch (...) {
    detach();
    log(LogLevel::kError, "job failed with an unknown exception", {{"job", id}});
    try {
      store_.transition(id, JobState::kFailed, now_ms(), "", "unknown error");
    } catch (...) {
    }
  }
  bool deleted;
  {
    std::lock_guard lock(mutex_);
    deleted = slot->delete_requested;
  }
  if (deleted) files_.remove(id);
  {
    std::lock_guard lock(mutex_);
    slot->done = true;
  }
  cv_.notify_all();
}

std::optional<JobProgress> Scheduler::live_progress(const std::string& id) const {
  std::lock_guard lock(mutex_);
  auto it = running_.find(id);
  if (it == running_.end()) return std::nullopt;
  return it->second->progress;
}

Scheduler::CancelResult Scheduler::cancel(const std::string& id) {
  std::lock_guard lock(mutex_);
  if (auto it = running_.find(id); it != running_.end()) {
    it->second->cancel_requested = true;
    if (it->second->session) it->second->session->cancel();
    return CancelResult::kCancelling;
  }
  // Not rendering here, and claims happen under this lock: a queued job stays queued until we are done.
  if (store_.transition(id, JobState::kCancelled, now_ms(), "cancelled")) {
    log(LogLevel::kInfo, "queued job cancelled", {{"job", id}});
    return CancelResult::kCancelled;
  }
  return store_.get(id) ? CancelResult::kAlreadyFinished : CancelResult::kUnknown;
}

bool Scheduler::remove(const std::string& id) {
  std::lock_guard lock(mutex_);
  if (auto it = running_.find(id); it != running_.end()) {
    it->second->delete_requested = true;
    if (it->second->session) it->second->session->cancel();
    store_.remove(id);
    return true;  // the render's thread removes the files once it has stopped writing them
  }
  if (!store_.remove(id)) return false;
  files_.remove(id);
  log(LogLevel::kInfo, "job deleted", {{"job", id}});
  return true;
}

}  // namespace tessera::server
