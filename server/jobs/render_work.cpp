#include "server/jobs/render_work.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <new>

#include <nlohmann/json.hpp>

#include "renderer/frames.h"
#include "renderer/job.h"
#include "renderer/output.h"
#include "renderer/scene.h"
#include "renderer/scene_error.h"
#include "renderer/scene_loader.h"
#include "server/jobs/checkpoint.h"
#include "server/jobs/job_results.h"

namespace tessera::server {

using nlohmann::json;

RenderRequest render_request(const JobRecord& record, int64_t epoch) {
  RenderRequest r;
  r.id = record.id;
  r.unit = record.unit;
  r.units = record.units;
  r.epoch = epoch;
  r.settings = record.settings;
  r.outputs = record.outputs;
  r.document = record.document;
  r.unit_first_sample = record.unit_first_sample;
  r.unit_samples = record.unit_samples;
  r.unit_checkpoint_epoch = record.unit_checkpoint_epoch;
  return r;
}

json render_request_to_json(const RenderRequest& r) {
  return {{"id", r.id},
          {"unit", r.unit},
          {"units", r.units},
          {"epoch", r.epoch},
          {"settings", r.settings},
          {"outputs", r.outputs},
          {"document", r.document},
          {"unit_first_sample", r.unit_first_sample},
          {"unit_samples", r.unit_samples},
          {"unit_checkpoint_epoch", r.unit_checkpoint_epoch}};
}

RenderRequest render_request_from_json(const json& j) {
  RenderRequest r;
  j.at("id").get_to(r.id);
  j.at("unit").get_to(r.unit);
  j.at("units").get_to(r.units);
  j.at("epoch").get_to(r.epoch);
  j.at("settings").get_to(r.settings);
  j.at("outputs").get_to(r.outputs);
  j.at("document").get_to(r.document);
  j.at("unit_first_sample").get_to(r.unit_first_sample);
  j.at("unit_samples").get_to(r.unit_samples);
  j.at("unit_checkpoint_epoch").get_to(r.unit_checkpoint_epoch);
  return r;
}

JobFile frame_done_file(const OutputSpec& outputs) {
  return outputs.exr ? JobFile::kResultExr : JobFile::kResultPng;
}

RenderSettings run_settings(const RenderRequest& request) {
  RenderSettings s = render_settings_from_text(request.settings);
  // A unit of a frame range renders whole frames (work_units.h).
  if (request.unit >= 0 && !renders_frames(s)) {
    // One unit: its range of the job's sample indices (work_units.h).
    s.first_sample += request.unit_first_sample;
    s.job_spp = s.spp;  // every unit's rays have the whole job's texture footprints
    s.spp = request.unit_samples;
  }
  return s;
}

uint64_t run_settings_hash(const RenderRequest& request) {
  return request.unit >= 0 ? unit_settings_hash(request.settings, request.unit) : fnv1a64(request.settings);
}

// Doubles are written with the digits that read back to the same value (nlohmann::json), so that a worker's
// progress reaches the store as the render measured it.
json render_progress_to_json(const RenderProgress& p) {
  return {{"pass", p.pass},
          {"samples_done", p.samples_done},
          {"samples_total", p.samples_total},
          {"elapsed_s", p.elapsed_s},
          {"eta_s", p.eta_s},
          {"samples_per_s", p.samples_per_s}};
}

RenderProgress render_progress_from_json(const json& j) {
  RenderProgress p;
  j.at("pass").get_to(p.pass);
  j.at("samples_done").get_to(p.samples_done);
  j.at("samples_total").get_to(p.samples_total);
  j.at("elapsed_s").get_to(p.elapsed_s);
  j.at("eta_s").get_to(p.eta_s);
  j.at("samples_per_s").get_to(p.samples_per_s);
  return p;
}

bool RunControl::stop_requested() const {
  std::lock_guard lock(mutex_);
  return stop_;
}

bool RunControl::cancel_requested() const {
  std::lock_guard lock(mutex_);
  return cancel_;
}

void RunControl::request(bool cancel) {
  std::lock_guard lock(mutex_);
  (cancel ? cancel_ : stop_) = true;
  if (deliver_) deliver_(cancel);
}

RunControl::Attachment RunControl::attach(std::function<void(bool cancel)> deliver) {
  std::lock_guard lock(mutex_);
  deliver_ = std::move(deliver);
  if (stop_) deliver_(false);
  if (cancel_) deliver_(true);
  return Attachment(this);
}

RunControl::Attachment::~Attachment() {
  if (!control_) return;
  std::lock_guard lock(control_->mutex_);
  control_->deliver_ = nullptr;
}

const char* run_outcome_name(RunOutcome outcome) {
  switch (outcome) {
    case RunOutcome::kRendered:
      return "rendered";
    case RunOutcome::kInterrupted:
      return "interrupted";
    case RunOutcome::kFailed:
      return "failed";
    case RunOutcome::kCrashed:
      return "crashed";
  }
  return "failed";
}

std::optional<RunOutcome> run_outcome_from_name(std::string_view name) {
  for (RunOutcome o : {RunOutcome::kRendered, RunOutcome::kInterrupted, RunOutcome::kFailed, RunOutcome::kCrashed})
    if (name == run_outcome_name(o)) return o;
  return std::nullopt;
}

json run_end_to_json(const RunEnd& end) {
  return {{"outcome", run_outcome_name(end.outcome)},
          {"reason", stop_reason_name(end.reason)},
          {"progress", render_progress_to_json(end.progress)},
          {"written", end.written},
          {"error", end.error},
          {"input_refused", end.input_refused}};
}

std::optional<RunEnd> run_end_from_json(const json& j) {
  const auto outcome = run_outcome_from_name(j.at("outcome").get<std::string>());
  if (!outcome) return std::nullopt;
  RunEnd end;
  end.outcome = *outcome;
  end.reason = stop_reason_from_name(j.at("reason").get<std::string>()).value_or(StopReason::kSamples);
  end.progress = render_progress_from_json(j.at("progress"));
  j.at("written").get_to(end.written);
  j.at("error").get_to(end.error);
  j.at("input_refused").get_to(end.input_refused);
  return end;
}

std::string describe_bytes(uint64_t bytes) {
  char buf[64];
  if (bytes >= (1ull << 30))
    std::snprintf(buf, sizeof buf, "%.3g GiB", static_cast<double>(bytes) / static_cast<double>(1ull << 30));
  else
    std::snprintf(buf, sizeof buf, "%.3g MiB", static_cast<double>(bytes) / static_cast<double>(1ull << 20));
  return buf;
}

namespace {

// The run's checkpoint, restored into `session` when it is one of these settings; what it held, to `listener`.
void resume(const RenderRequest& request, const JobFiles& files, const RenderSettings& settings, uint64_t hash,
            RenderSession& session, RunListener& listener) {
  std::optional<std::string> checkpoint;
  if (request.unit < 0)
    checkpoint = files.read(request.id, JobFile::kCheckpoint);
  else if (request.unit_checkpoint_epoch > 0)
    checkpoint = files.read_unit(request.id, request.unit, request.unit_checkpoint_epoch);
  auto cp = checkpoint ? decode_checkpoint(*checkpoint, settings.width, settings.height, hash) : std::nullopt;
  if (!cp) {
    listener.resumed(std::nullopt, checkpoint.has_value());
    return;
  }
  session.restore(std::move(cp->film), cp->passes, cp->elapsed_s);
  listener.resumed(session.progress(), false);
}

// A pass's checkpoint (a unit's, named by its run's epoch: the store's record of the run's progress makes it the
// unit's) and, of a job rendered whole, its preview. A split job's preview is the merge of its done units.
void write_pass(const RenderRequest& request, const JobFiles& files, const OutputPipeline& outputs,
                const RenderProgress& p, const Film& film, const RenderSettings& settings, uint64_t hash) {
  const std::string checkpoint = encode_checkpoint(film, p.pass, p.elapsed_s, hash, settings);
  if (request.unit >= 0) {
    files.write_unit(request.id, request.unit, request.epoch, checkpoint);
  } else {
    files.write(request.id, JobFile::kCheckpoint, checkpoint);
    files.write(request.id, JobFile::kPreviewPng, outputs.preview_png(film));
  }
}

RunEnd failed(std::string message, bool input_refused, const RenderProgress& progress) {
  RunEnd end;
  end.outcome = RunOutcome::kFailed;
  end.error = std::move(message);
  end.input_refused = input_refused;
  end.progress = progress;
  return end;
}

// A load for a run: the scene `load(options)` reads, stopped by any request of `control` (a load has no pass to
// finish); its seconds, to `load_s`.
std::shared_ptr<const Scene> load_for_run(
    const RenderEnvironment& env, RunControl& control, double& load_s,
    const std::function<std::shared_ptr<const Scene>(const SceneLoadOptions&)>& load) {
  std::stop_source load_stop;
  auto attached = control.attach([&](bool) { load_stop.request_stop(); });
  SceneLoadOptions options;
  options.resolve_asset = env.resolve_asset;
  options.max_gltf_instances = env.max_gltf_instances;
  options.stop = load_stop.get_token();
  const auto load_start = std::chrono::steady_clock::now();
  auto scene = load(options);
  load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - load_start).count();
  return scene;
}

// While it lives, a stop request of `control` ends `session` after its pass under way, a cancel within a tile's time.
RunControl::Attachment attach_session(RunControl& control, RenderSession& session) {
  return control.attach([&session](bool cancel) {
    if (cancel)
      session.cancel();
    else
      session.stop();
  });
}

// The frames of a run of a frame range, in order (renderer/frames.h): its unit's (work_units.h: unit_frames), or every
// frame of a range of one unit. A frame whose files exist was rendered by an earlier run (of its unit, before that
// run's daemon stopped or its worker died) and is not rendered again. Each frame is loaded at its
// time and rendered whole from sample 0 with the job's seed, so that its image is the still of that time, bit for
// bit; its outputs are written under their numbered names, the job's preview becomes its PNG, and the job's progress
// counts every frame's samples. A frame that fails is rendered again, up to kFrameAttempts times; a frame the
// renderer refuses (its input) or that fails every attempt fails the run, naming the frame.
class FrameRangeRender {
 public:
  FrameRangeRender(const RenderRequest& request, const RenderEnvironment& env, RunControl& control,
                   RunListener& listener)
      : request_(request),
        env_(env),
        control_(control),
        listener_(listener),
        settings_(run_settings(request)),
        spec_(output_spec_from_text(request.outputs)),
        outputs_(settings_, spec_),
        document_(json::parse(request.document)),
        frames_(request.unit >= 0 ? unit_frames(settings_, request.unit) : frame_numbers(*settings_.frames)),
        padding_(frame_padding(*settings_.frames)) {}

  RunEnd run() {
    RunEnd end;
    // Which frames earlier runs finished, looked up once: one open of a file a frame.
    std::vector<bool> finished(frames_.size());
    for (size_t i = 0; i < frames_.size(); ++i) finished[i] = done(frames_[i]);
    const auto done_before = static_cast<uint32_t>(std::count(finished.begin(), finished.end(), true));
    progress_.samples_total =
        static_cast<uint32_t>(std::min<uint64_t>(uint64_t{settings_.spp} * frames_.size(), UINT32_MAX));
    progress_.samples_done = done_before * settings_.spp;
    samples_before_ = progress_.samples_done;
    listener_.resumed(done_before ? std::optional<RenderProgress>(progress_) : std::nullopt, false);
    for (size_t i = 0; i < frames_.size(); ++i) {
      if (finished[i]) continue;
      const int64_t frame = frames_[i];
      std::string error;
      bool input_refused = false;
      for (int attempt = 1; attempt <= kFrameAttempts; ++attempt) {
        error.clear();
        try {
          const StopReason reason = render_frame(frame);
          if (reason == StopReason::kStopped || reason == StopReason::kCancelled) {
            end.outcome = RunOutcome::kInterrupted;
            end.reason = reason;
            end.progress = progress_;
            return end;
          }
          break;
        } catch (const LoadStopped&) {
          throw;
        } catch (const SceneError& e) {
          error = e.pointer().empty() ? e.what() : e.pointer() + ": " + e.what();
          input_refused = true;
          break;
        } catch (const std::exception& e) {
          error = e.what();
          listener_.frame(frame, failure_line(attempt, error));
        }
      }
      if (!error.empty()) {
        end.outcome = RunOutcome::kFailed;
        end.error = "frame " + std::to_string(frame) + ": " + error;
        end.input_refused = input_refused;
        end.progress = progress_;
        return end;
      }
    }
    end.outcome = RunOutcome::kRendered;
    end.reason = StopReason::kSamples;
    end.progress = progress_;
    end.progress.eta_s = 0;
    end.written = " " + std::to_string(frames_.size()) + " frames";
    return end;
  }

 private:
  static std::string failure_line(int attempt, const std::string& error) {
    return "failed (attempt " + std::to_string(attempt) + " of " + std::to_string(kFrameAttempts) + "): " + error +
           (attempt < kFrameAttempts ? "; rendering it again" : "");
  }

  bool done(int64_t frame) const {
    return env_.files->open_frame(request_.id, frame_done_file(spec_), frame, padding_) != nullptr;
  }

  // The frame's scene, posed at its time, with its acceleration structure; load_s_ is how long that took.
  std::shared_ptr<const Scene> load(int64_t frame) {
    auto scene = load_for_run(env_, control_, load_s_, [&](const SceneLoadOptions& options) {
      return load_frame_scene(document_, settings_, frame, options);
    });
    if (!loaded_) listener_.loaded(scene->warnings, load_s_);
    loaded_ = true;
    return scene;
  }

  // One frame: its passes reported as the job's progress over all frames; its files written once it is whole.
  StopReason render_frame(int64_t frame) {
    listener_.frame(frame,
                    "rendering at " + std::to_string(frame_time(frame, settings_.fps, 0)) + " s of its animation");
    RenderSession session(load(frame), settings_, *env_.pool);
    const uint32_t base = progress_.samples_done;
    const double elapsed_base = progress_.elapsed_s;
    const uint32_t passes_base = progress_.pass;
    StopReason reason;
    {
      auto attached = attach_session(control_, session);
      reason = session.run([&](const RenderProgress& p, const Film&) {
        progress_.pass = passes_base + p.pass;
        progress_.samples_done = base + p.samples_done;
        progress_.elapsed_s = elapsed_base + p.elapsed_s;
        progress_.samples_per_s = p.samples_per_s;
        const double rendered = static_cast<double>(progress_.samples_done - samples_before_);
        progress_.eta_s = rendered > 0 ? progress_.elapsed_s / rendered *
                                             static_cast<double>(progress_.samples_total - progress_.samples_done)
                                       : 0;
        listener_.pass(progress_, "");
      });
    }
    if (reason == StopReason::kStopped || reason == StopReason::kCancelled) {
      progress_.samples_done = base;
      return reason;
    }
    write_frame(frame, outputs_.image(session.film()));
    progress_.samples_done = base + settings_.spp;
    listener_.frame(frame, "done in " + std::to_string(session.progress().elapsed_s) + " s (scene load and BVH " +
                               std::to_string(load_s_) + " s)");
    return reason;
  }

  // Its passes' PNGs and the formats other than the one that marks it done, then that one, then the preview.
  void write_frame(int64_t frame, const Image& image) {
    const JobFile last = frame_done_file(spec_);
    std::optional<std::string> last_bytes;
    outputs_.publish_passes(image, [&](std::string_view pass, std::string_view png) {
      if (const auto f = pass_file(pass)) env_.files->write_frame(request_.id, *f, frame, padding_, png);
    });
    outputs_.publish(image, [&](ImageFormat format, std::string_view bytes) {
      const JobFile f = result_file(format);
      if (f == last)
        last_bytes.emplace(bytes);
      else
        env_.files->write_frame(request_.id, f, frame, padding_, bytes);
    });
    if (last_bytes) env_.files->write_frame(request_.id, last, frame, padding_, *last_bytes);
    env_.files->write(request_.id, JobFile::kPreviewPng, outputs_.preview_png(image));
  }

  const RenderRequest& request_;
  const RenderEnvironment& env_;
  RunControl& control_;
  RunListener& listener_;
  const RenderSettings settings_;
  const OutputSpec spec_;
  const OutputPipeline outputs_;
  const json document_;
  const std::vector<int64_t> frames_;
  const int padding_;
  RenderProgress progress_;
  uint32_t samples_before_ = 0;  // of the frames earlier runs rendered
  bool loaded_ = false;
  double load_s_ = 0;  // of the frame under way
};

}  // namespace

void perform_render(const RenderRequest& request, const RenderEnvironment& env, RunControl& control,
                    RunListener& listener) {
  RenderProgress progress;
  RunEnd end;
  try {
    const RenderSettings settings = run_settings(request);
    if (renders_frames(settings)) {
      listener.ended(FrameRangeRender(request, env, control, listener).run());
      return;
    }
    const uint64_t hash = run_settings_hash(request);
    double load_s = 0;
    const std::shared_ptr<const Scene> scene = load_for_run(env, control, load_s, [&](const SceneLoadOptions& options) {
      return load_job_scene(json::parse(request.document), settings, options);
    });
    listener.loaded(scene->warnings, load_s);
    RenderSession session(scene, settings, *env.pool);
    resume(request, *env.files, settings, hash, session, listener);
    const OutputPipeline outputs(settings, output_spec_from_text(request.outputs));
    // The pass of this run's last checkpoint (passes, not samples: with adaptive sampling a pass may leave the
    // mean sample count as it was); nothing until it writes one (a unit's film must be written under
    // the run's own epoch, even when it restored all its samples from another run's checkpoint).
    std::optional<uint32_t> checkpointed;
    StopReason reason;
    {
      auto attached = attach_session(control, session);
      reason = session.run([&](const RenderProgress& p, const Film& film) {
        std::string error;
        try {
          write_pass(request, *env.files, outputs, p, film, settings, hash);
          checkpointed = p.pass;
        } catch (const std::exception& e) {
          // A missed checkpoint or preview (a full disk) is not worth the render: the last good checkpoint stays,
          // and the next pass writes both again.
          error = e.what();
        }
        listener.pass(p, error);
      });
    }
    progress = session.progress();
    end.progress = progress;
    end.reason = reason;
    if (reason == StopReason::kStopped || reason == StopReason::kCancelled) {
      end.outcome = RunOutcome::kInterrupted;
    } else if (request.unit >= 0) {
      // A unit's film is its last checkpoint; written again if the last pass's could not be.
      if (checkpointed != progress.pass)
        env.files->write_unit(request.id, request.unit, request.epoch,
                              encode_checkpoint(session.film(), progress.pass, progress.elapsed_s, hash, settings));
      end.outcome = RunOutcome::kRendered;
    } else {
      // The outputs, staged under the run's epoch: published only once the store takes the run's end.
      end.written = stage_outputs(*env.files, request.id, outputs, outputs.image(session.film()), request.epoch);
      end.outcome = RunOutcome::kRendered;
    }
  } catch (const LoadStopped&) {
    end = RunEnd{};
    end.outcome = RunOutcome::kInterrupted;
    end.reason = StopReason::kCancelled;
  } catch (const std::bad_alloc&) {
    end = failed(env.memory_limit ? "the render needs more than the " + describe_bytes(env.memory_limit) +
                                        " memory limit of a render worker (--worker-memory)"
                                  : "the render needs more memory than this machine has",
                 true, progress);
  } catch (const std::exception& e) {
    std::string message = e.what();
    // The renderer refused the scene or an asset it names: the input is at fault, not this run.
    const auto* se = dynamic_cast<const SceneError*>(&e);
    if (se && !se->pointer().empty()) message = se->pointer() + ": " + message;
    end = failed(message, se != nullptr, progress);
  } catch (...) {
    end = failed("unknown error", false, progress);
  }
  listener.ended(end);
}

}  // namespace tessera::server
