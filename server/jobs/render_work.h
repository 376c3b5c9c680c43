// One run's render, apart from the daemon that claimed it: load the scene, resume from the run's checkpoint, render
// passes writing a checkpoint and a preview after each, and stage the outputs (a unit: keep its film). It touches only
// the job's files. The store, the leases and the job's log are the scheduler's, which hears of each step through a
// RunListener and stops the render through a RunControl.
//
// The daemon runs these steps in a supervised worker process (worker_process.h), so that a scene that crashes the
// renderer takes down that process alone, as render managers run their renderers (Flamenco, OpenCue, Deadline); tests
// of the scheduler run them on the scheduler's own thread (InProcessRunner).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "renderer/render_settings.h"
#include "renderer/session.h"
#include "renderer/thread_pool.h"
#include "server/files/job_files.h"
#include "server/store/job_store.h"
#include "server/store/work_units.h"

namespace tessera::server {

// What a run renders: the parts of its job's record a render reads, and the run's epoch (which names a unit's
// checkpoints and the outputs it stages).
struct RenderRequest {
  std::string id;
  int unit = -1;  // JobRecord::unit: -1 for a job rendered whole
  int units = 0;
  int64_t epoch = 0;
  std::string settings;  // JobRecord::settings, outputs and document, as stored
  std::string outputs;
  std::string document;
  uint32_t unit_first_sample = 0;
  uint32_t unit_samples = 0;
  int64_t unit_checkpoint_epoch = 0;  // the run whose checkpoint is the unit's; 0: none
};

RenderRequest render_request(const JobRecord& record, int64_t epoch);
nlohmann::json render_request_to_json(const RenderRequest& request);
// Throws nlohmann::json::exception for a document that is not one.
RenderRequest render_request_from_json(const nlohmann::json& j);

// The settings the run renders with: the job's, narrowed to a unit's range of the job's sample indices.
RenderSettings run_settings(const RenderRequest& request);
// What the run's checkpoints are checked against (checkpoint.h): the job's settings, and the unit.
uint64_t run_settings_hash(const RenderRequest& request);

nlohmann::json render_progress_to_json(const RenderProgress& progress);
RenderProgress render_progress_from_json(const nlohmann::json& j);

// Requests to stop a run, from any thread. They stick: one made before the render can take it (during the load, or
// before the run starts) is taken as soon as it can be.
class RunControl {
 public:
  // End after the pass under way, which is kept as the checkpoint; a load under way ends at once.
  void stop() { request(false); }
  // Give up the pass under way within a tile's time (the last checkpoint stays); a load under way ends at once.
  void cancel() { request(true); }
  bool stop_requested() const;
  bool cancel_requested() const;

  // While the returned object lives, `deliver(cancel)` takes the requests: those made already, at once, then each
  // new one. Called under the control's lock: it must only pass the request on.
  class Attachment {
   public:
    explicit Attachment(RunControl* control) : control_(control) {}
    Attachment(Attachment&& other) noexcept : control_(std::exchange(other.control_, nullptr)) {}
    Attachment& operator=(Attachment&&) = delete;
    ~Attachment();

   private:
    RunControl* control_;
  };
  [[nodiscard]] Attachment attach(std::function<void(bool cancel)> deliver);

 private:
  void request(bool cancel);
  mutable std::mutex mutex_;
  bool stop_ = false;
  bool cancel_ = false;
  std::function<void(bool)> deliver_;
};

enum class RunOutcome {
  kRendered,     // the render met its budget: outputs staged under the run's epoch (a unit: its film written)
  kInterrupted,  // stopped or cancelled (RunControl), or its load stopped: the last checkpoint stays
  kFailed,       // the scene, an asset or the outputs failed: `error` says why
  kCrashed,      // the process rendering it died (a worker's signal, exit, or limit): `error` says how
};
const char* run_outcome_name(RunOutcome outcome);
std::optional<RunOutcome> run_outcome_from_name(std::string_view name);

struct RunEnd {
  RunOutcome outcome = RunOutcome::kFailed;
  StopReason reason = StopReason::kSamples;  // of a rendered or interrupted run
  RenderProgress progress;
  std::string written;  // the output files staged, for the job's log (" result.png result.exr")
  std::string error;
  bool input_refused = false;  // failed on its input (the scene, an asset): it would fail the same way again
};
nlohmann::json run_end_to_json(const RunEnd& end);
// Nothing for an unknown outcome; throws nlohmann::json::exception for a document that is not one.
std::optional<RunEnd> run_end_from_json(const nlohmann::json& j);

// What a render reports, in this order: loaded (unless the load fails or stops), resumed, pass after each pass, and
// ended, exactly once whatever happens.
class RunListener {
 public:
  virtual ~RunListener() = default;
  virtual void loaded(const std::vector<std::string>& warnings, double load_s) = 0;
  // Its checkpoint was read: `restored` is its progress, nothing when there was none or it was `unusable`.
  virtual void resumed(const std::optional<RenderProgress>& restored, bool unusable) = 0;
  // A pass ended and its checkpoint and preview were written; `write_error` says why they were not, when not.
  virtual void pass(const RenderProgress& progress, const std::string& write_error) = 0;
  // A frame of a frame range (render_frames) started, ended or failed: `event` says which, for the job's log; the
  // passes reported after it are that frame's.
  virtual void frame(int64_t /*frame*/, const std::string& /*event*/) {}
  virtual void ended(const RunEnd& end) = 0;
};

// A frame range job (work_units.h: renders_frames): each frame is the still at its time (renderer/frames.h), rendered
// whole with the job's seed and written as numbered files (JobFiles::write_frame); a run renders the frames of its
// unit (unit_frames), or all of them for a range of one unit.
// How many times a run renders a frame that fails before the job fails naming it.
inline constexpr int kFrameAttempts = 3;
// The file whose presence says a frame is done: written after the frame's other files, so the frame's EXR when the
// job asks for one, else its PNG.
JobFile frame_done_file(const OutputSpec& outputs);

// What a render needs of the process that runs it.
struct RenderEnvironment {
  const JobFiles* files = nullptr;
  ThreadPool* pool = nullptr;
  // SceneLoadOptions::resolve_asset and max_gltf_instances.
  std::function<std::filesystem::path(const std::string& ref, const std::string& pointer)> resolve_asset;
  uint64_t max_gltf_instances = 1'000'000;
  // The memory a worker may take (RLIMIT_AS), for the message of a render that runs out of it; 0: not limited.
  uint64_t memory_limit = 0;
};

// The render's steps, on the calling thread; reports to `listener` (ended() last, always).
void perform_render(const RenderRequest& request, const RenderEnvironment& env, RunControl& control,
                    RunListener& listener);

// Where a run's render happens.
class RenderRunner {
 public:
  virtual ~RenderRunner() = default;
  // Renders, reporting to `listener` on the calling thread, until the render ends; `listener.ended()` last, always.
  virtual void run(const RenderRequest& request, RunControl& control, RunListener& listener) = 0;
  virtual int threads() const = 0;
  // "in a worker process", for the job's log.
  virtual const char* where() const = 0;
};

// On the caller's thread, in the daemon's process: for tests of the scheduler, and where a crash may take the process.
class InProcessRunner final : public RenderRunner {
 public:
  explicit InProcessRunner(RenderEnvironment env) : env_(std::move(env)) {}
  void run(const RenderRequest& request, RunControl& control, RunListener& listener) override {
    perform_render(request, env_, control, listener);
  }
  int threads() const override { return env_.pool->size(); }
  const char* where() const override { return "in process"; }

 private:
  RenderEnvironment env_;
};

// "8 GiB", "512 MiB": a size for messages.
std::string describe_bytes(uint64_t bytes);

}  // namespace tessera::server
