#include "server/jobs/job_service.h"

#include <algorithm>
#include <charconv>
#include <filesystem>

#include "proto/contract.h"
#include "server/base/job_id.h"
#include "server/base/log.h"
#include "server/base/time_format.h"
#include "server/files/assets.h"
#include "server/files/job_log.h"
#include "server/jobs/job_json.h"
#include "server/store/work_units.h"

namespace tessera::server {

using nlohmann::json;

namespace {

// The frame range of a job that renders one (work_units.h: renders_frames); nothing otherwise.
std::optional<FrameRange> frame_range_of(const JobRecord& job) {
  try {
    const RenderSettings settings = render_settings_from_text(job.settings);
    if (renders_frames(settings)) return settings.frames;
  } catch (const std::runtime_error&) {
    // A record whose settings cannot be read renders nothing that can be served.
  }
  return std::nullopt;
}

// "1-48" or "1-48 step 2".
std::string describe_range(const FrameRange& range) {
  return std::to_string(range.start) + "-" + std::to_string(range.end) +
         (range.step > 1 ? " step " + std::to_string(range.step) : "");
}

Problem priority_needs_admin(int priority, int max_user_priority) {
  return Problem{403,
                 "priority " + std::to_string(priority) + " is above " + std::to_string(max_user_priority) +
                     ", which needs an admin token",
                 "/priority"};
}

bool may_see(const Caller& caller, const JobRecord& job) {
  return caller.admin || job.owner == caller.name;
}

// At most `max` bytes of `s`, cut before a UTF-8 character rather than inside one.
std::string utf8_prefix(const std::string& s, size_t max) {
  if (s.size() <= max) return s;
  size_t n = max;
  while (n > 0 && (static_cast<unsigned char>(s[n]) & 0xC0) == 0x80) --n;
  return s.substr(0, n);
}

// What a job is called when its document does not say ("name"): the glTF file it renders as it was uploaded, else
// the types of its materials, else its kind.
std::string default_job_name(const json& doc, const AssetStore& assets) {
  constexpr size_t kMaxNameBytes = 200;  // job.schema.json's maxLength for "name"
  const json scene = doc.value("scene", json::object());
  if (scene.is_object() && scene.contains("gltf") && scene["gltf"].is_string()) {
    const std::string ref = scene["gltf"];
    if (auto info = is_asset_id(ref) ? assets.get(ref) : std::nullopt) return utf8_prefix(info->main, kMaxNameBytes);
    return utf8_prefix(std::filesystem::path(ref).filename().string(), kMaxNameBytes);
  }
  std::string types;
  const json one = doc.value("material", json::object());
  for (const json& m : doc.contains("materials") ? doc["materials"] : json::array({one}))
    if (m.is_object() && m.contains("type") && m["type"].is_string())
      types += (types.empty() ? "" : ", ") + m["type"].get<std::string>();
  if (!types.empty()) return utf8_prefix(types, kMaxNameBytes);
  return doc.value("kind", "scene");
}

}  // namespace

JobService::JobService(JobStore& store, const JobFiles& files, AssetStore& assets, Scheduler& scheduler,
                       EventBus& events, Metrics& metrics, JobServiceOptions options)
    : store_(store),
      files_(files),
      assets_(assets),
      scheduler_(scheduler),
      events_(events),
      metrics_(metrics),
      options_(options),
      log_(files, options.node),
      results_(store, files, options.node) {
  SchedulerHooks hooks;
  hooks.state_changed = [this](const std::string& id) { publish_state(id); };
  hooks.progress = [this](const std::string& id, const JobProgress& p) {
    auto job = store_.get(id);
    if (!job) return;
    json status = job_status_json(*job, p);
    events_.publish(id, job->owner, "progress", json{{"id", id}, {"progress", status["progress"]}}.dump());
  };
  hooks.preview = [this](const std::string& id, uint32_t pass) {
    auto job = store_.get(id);
    if (!job) return;
    events_.publish(
        id, job->owner, "preview",
        json{{"id", id}, {"pass", pass}, {"url", "/v1/jobs/" + id + "/preview.png?pass=" + std::to_string(pass)}}
            .dump());
  };
  hooks.samples_rendered = [this](uint64_t n) { metrics_.add_samples(n); };
  hooks.job_ended = [this](double render_s, const std::function<bool()>& record) {
    return metrics_.record_job_end(render_s, record);
  };
  hooks.store_write_failed = [this] { metrics_.count_job_store_error(); };
  scheduler_.set_hooks(std::move(hooks));
}

JobService::~JobService() {
  // Its render threads call the hooks, which use this service.
  scheduler_.shutdown();
}

// ---- submitting -------------------------------------------------------------------------------------------------

std::optional<Problem> JobService::store_uploads(const Caller& caller, json& doc, std::vector<UploadFile> files) {
  // An asset reference that is no asset id names a file this request should have sent: said so, naming the file,
  // where the schema would only say that the reference is not an asset id.
  const std::vector<std::string> refs = proto::asset_refs(doc);
  for (const std::string& at : refs) {
    const json::json_pointer pointer{at};
    const std::string name = doc[pointer].get<std::string>();
    if (is_asset_id(name) ||
        std::any_of(files.begin(), files.end(), [&](const UploadFile& f) { return f.name == name; }))
      continue;
    std::string field(at.substr(1));
    std::replace(field.begin(), field.end(), '/', '.');
    return Problem{422,
                   field + " names " + name +
                       ", which this request did not send: add it as a file part, or give an uploaded asset's id",
                   at};
  }
  if (files.empty()) return std::nullopt;
  if (!doc.is_object() || !doc.contains("scene") || !doc["scene"].is_object())
    return Problem{422, "uploaded files need a scene job that names them", "/scene"};
  json& scene = doc["scene"];
  // A file the job names at a reference other than scene.gltf (an environment map, a medium's grid) becomes an asset
  // of its own; the rest is the glTF asset.
  for (const std::string& at : refs) {
    if (at == "/scene/gltf") continue;
    const json::json_pointer pointer{at};
    const std::string name = doc[pointer].get<std::string>();
    auto it = std::find_if(files.begin(), files.end(), [&](const UploadFile& f) { return f.name == name; });
    if (it == files.end()) continue;
    std::vector<UploadFile> one;
    one.push_back(std::move(*it));
    files.erase(it);
    auto stored = assets_.store(std::move(one), caller.name);
    if (auto* p = std::get_if<Problem>(&stored)) return *p;
    const std::string id = std::get<StoredAsset>(stored).info.id;
    // Every reference to the same file takes its id (a grid shared by several objects).
    for (const std::string& other : refs)
      if (other != "/scene/gltf" && doc[json::json_pointer(other)] == name) doc[json::json_pointer(other)] = id;
  }
  if (files.empty()) return std::nullopt;
  const bool named = scene.contains("gltf") && scene["gltf"].is_string() &&
                     std::any_of(files.begin(), files.end(),
                                 [&](const UploadFile& f) { return f.name == scene["gltf"].get<std::string>(); });
  auto stored = assets_.store(std::move(files), caller.name);
  if (auto* p = std::get_if<Problem>(&stored)) return *p;
  const AssetInfo& info = std::get<StoredAsset>(stored).info;
  if (named && info.kind == "gltf") scene["gltf"] = info.id;
  return std::nullopt;
}

std::variant<Submitted, Problem> JobService::submit(const Caller& caller, SubmitRequest request) {
  return writing([&]() -> std::variant<Submitted, Problem> {
    if (!scheduler_.accepting()) return Problem{503, "the daemon is shutting down", std::nullopt};
    const std::string& key = request.idempotency_key;
    auto existing = [&](const JobRecord& job) -> std::variant<Submitted, Problem> {
      if (job.request_hash != request.request_hash)
        return Problem{422, "this Idempotency-Key was used with another request body", std::nullopt};
      return Submitted{job, status(job), false};
    };
    if (!key.empty())
      if (auto job = store_.find_by_idempotency_key(caller.name, key)) return existing(*job);

    const AcceptedJob& accepted = request.job;
    if (accepted.priority > options_.max_user_priority && !caller.admin)
      return priority_needs_admin(accepted.priority, options_.max_user_priority);
    if (auto full = queue_full(caller.name)) return *full;
    JobRecord job;
    job.id = new_job_id();
    const json& name = accepted.document.contains("name") ? accepted.document["name"] : json();
    job.name = name.is_string() ? name.get<std::string>() : default_job_name(accepted.document, assets_);
    job.kind = accepted.kind;
    job.priority = accepted.priority;
    job.created_at_ms = now_ms();
    job.document = accepted.document.dump();
    job.settings = render_settings_text(accepted.settings);
    job.outputs = output_spec_text(accepted.outputs);
    job.progress.samples_total = job_samples_total(accepted.settings);
    // A frame range is split into units of frames on every store; on a store several nodes share, a large still is
    // split into units of samples they render at once (work_units.h).
    job.units = job_units(accepted.settings, store_.splits_jobs() ? options_.unit_pixel_samples : 0);
    job.owner = caller.name;
    job.warnings = json(accepted.warnings).dump();
    job.idempotency_key = key;
    job.request_hash = request.request_hash;
    try {
      store_.create(job);
    } catch (const std::exception& e) {
      // The same key raced in from another connection: that request's job is this one's.
      if (!key.empty())
        if (auto raced = store_.find_by_idempotency_key(caller.name, key)) return existing(*raced);
      // The disk filled after the --min-free-disk check: the insert was rolled back whole, so, as the check's refusal,
      // nothing of the job exists (assets a multipart submission stored stay: whole, and found again by a retry).
      if (const auto* se = dynamic_cast<const JobStoreError*>(&e); se && se->out_of_space()) {
        metrics_.count_job_store_error();
        log(LogLevel::kWarn, "job refused: the job store ran out of space", {{"error", e.what()}});
        return insufficient_storage("the data directory's disk ran out of space while the job was stored",
                                    request.files_stored ? "the job was not stored; the files uploaded with it were, "
                                                           "whole, and a retry reuses them"
                                                         : "nothing was stored");
      }
      throw;
    }
    scheduler_.wake();
    log(LogLevel::kInfo, "job queued",
        {{"job", job.id},
         {"name", job.name},
         {"kind", job.kind},
         {"priority", job.priority},
         {"owner", job.owner},
         {"render", render_settings_to_json(accepted.settings)}});
    // The job exists from here on: a store that fails as it is read back costs the answer its queue position (and the
    // event its watchers), not a failure whose retry, without an Idempotency-Key, would queue the job twice.
    Submitted out{job, json(), true};
    try {
      publish_state(job.id);
      if (auto stored = store_.get(job.id)) out.job = *stored;
      out.status = status(out.job);
    } catch (const JobStoreError& e) {
      metrics_.count_job_store_error();
      log(LogLevel::kWarn, "job queued, but the job store failed as it was read back",
          {{"job", job.id}, {"error", e.what()}});
      out.status = job_status_json(job);
    }
    return out;
  });
}

// ---- reading ----------------------------------------------------------------------------------------------------

std::optional<JobRecord> JobService::find(const Caller& caller, const std::string& id) {
  if (!is_valid_job_id(id)) return std::nullopt;
  std::optional<JobRecord> job = store_.get(id);
  if (!job || !may_see(caller, *job)) return std::nullopt;
  return job;
}

json JobService::status(const JobRecord& job) {
  std::optional<int> position;
  if (job.state == JobState::kQueued) position = store_.queue_position(job.id);
  // A split job's units (a store that splits jobs; empty for a job rendered whole).
  std::vector<UnitRecord> units;
  if (store_.splits_jobs() || frame_range_of(job)) units = store_.units(job.id);
  return job_status_json(job, scheduler_.live_progress(job.id), position, units, now_ms());
}

JobPage JobService::list(const Caller& caller, JobFilter filter) {
  if (!caller.admin) filter.owner = caller.name;
  const int limit = filter.limit;
  filter.limit = limit + 1;  // one more tells whether another page exists
  std::vector<JobRecord> jobs = store_.list(filter);
  JobPage page;
  if (static_cast<int>(jobs.size()) > limit) {
    jobs.resize(static_cast<size_t>(limit));
    page.next_before_seq = jobs.back().seq;
  }
  for (const JobRecord& job : jobs) page.jobs.push_back(status(job));
  return page;
}

std::map<JobState, int> JobService::counts() {
  return store_.count_by_state();
}

std::variant<std::unique_ptr<FileReader>, Problem> JobService::preview(const JobRecord& job) {
  if (auto file = files_.open(job.id, JobFile::kPreviewPng)) return file;
  if (!is_terminal(job.state))
    return Problem{
        409, std::string("the job is ") + job_state_name(job.state) + "; a preview exists after its first render pass",
        std::nullopt};
  return Problem{404, "this job has no preview (it ended before its first pass)", std::nullopt};
}

std::optional<std::string> JobService::document(const JobRecord& job) {
  auto stored = store_.get(job.id, true);
  if (!stored) return std::nullopt;
  return stored->document;
}

std::unique_ptr<FileReader> JobService::job_log(const JobRecord& job) {
  auto text = JobLog::read(files_, job.id);
  return text ? bytes_reader(std::move(*text)) : nullptr;
}

namespace {

// Why a job has no results yet, or nothing: a cancelled job keeps the image of its last complete pass, if it had one
// (partial results).
std::optional<Problem> results_not_ready(const JobRecord& job) {
  if (job.state == JobState::kSucceeded || job.state == JobState::kCancelled) return std::nullopt;
  return Problem{409,
                 std::string("the job is ") + job_state_name(job.state) +
                     "; results exist once it has succeeded (or, partial, once it was cancelled after a pass)",
                 std::nullopt};
}

}  // namespace

std::variant<std::unique_ptr<FileReader>, Problem> JobService::result(const JobRecord& job, JobFile file) {
  if (auto range = frame_range_of(job))
    return Problem{409,
                   "the job renders frames " + describe_range(*range) + ": each frame has its results, at /v1/jobs/" +
                       job.id + "/frames/{frame}/" + job_file_name(file),
                   std::nullopt};
  if (auto problem = results_not_ready(job)) return *problem;
  const std::string format = file == JobFile::kResultExr ? "exr" : "png";
  bool asked = false;
  try {
    const OutputSpec outputs = output_spec_from_text(job.outputs);
    asked = file == JobFile::kResultExr ? outputs.exr : outputs.png;
  } catch (const std::runtime_error&) {
    // A record whose outputs cannot be read asked for nothing that can be served.
  }
  if (!asked) return Problem{404, "the job did not ask for a " + format + " output", std::nullopt};
  return published_result(job, file);
}

std::variant<std::unique_ptr<FileReader>, Problem> JobService::frame_result(const JobRecord& job,
                                                                            std::string_view frame, JobFile file,
                                                                            std::string_view pass) {
  const auto range = frame_range_of(job);
  if (!range) return Problem{404, "the job renders no frame range (render.frames)", std::nullopt};
  int64_t f = 0;
  const auto [end, ec] = std::from_chars(frame.data(), frame.data() + frame.size(), f);
  const bool in_range = ec == std::errc() && end == frame.data() + frame.size() && f >= range->start &&
                        f <= range->end && (f - range->start) % range->step == 0;
  if (!in_range)
    return Problem{404, "frame " + std::string(frame) + " is not one of the job's frames " + describe_range(*range),
                   std::nullopt};
  JobFile wanted = file;
  bool asked = false;
  try {
    if (!pass.empty()) {
      const std::vector<std::string> aovs = render_settings_from_text(job.settings).aovs;
      const auto f_pass = pass_file(pass);
      asked = f_pass && std::find(aovs.begin(), aovs.end(), pass) != aovs.end();
      if (f_pass) wanted = *f_pass;
    } else {
      const OutputSpec outputs = output_spec_from_text(job.outputs);
      asked = file == JobFile::kResultExr ? outputs.exr : outputs.png;
    }
  } catch (const std::runtime_error&) {
    // A record that cannot be read asked for nothing that can be served.
  }
  if (!asked)
    return Problem{
        404,
        std::string("the job did not ask for ") + (pass.empty() ? std::string(job_file_name(file)) : std::string(pass)),
        std::nullopt};
  if (auto reader = files_.open_frame(job.id, wanted, f, frame_padding(*range))) return reader;
  return Problem{404, "frame " + std::to_string(f) + " is not done (the job is " + job_state_name(job.state) + ")",
                 std::nullopt};
}

std::variant<std::unique_ptr<FileReader>, Problem> JobService::pass(const JobRecord& job, std::string_view name) {
  if (auto range = frame_range_of(job))
    return Problem{409,
                   "the job renders frames " + describe_range(*range) + ": each frame has its passes, at /v1/jobs/" +
                       job.id + "/frames/{frame}/aovs/" + std::string(name) + ".png",
                   std::nullopt};
  std::vector<std::string> aovs;
  try {
    aovs = render_settings_from_text(job.settings).aovs;
  } catch (const std::runtime_error&) {
    // A record whose settings cannot be read asked for no pass that can be served.
  }
  const auto f = pass_file(name);
  if (!f || std::find(aovs.begin(), aovs.end(), name) == aovs.end()) {
    std::string asked;
    for (const std::string& a : aovs) asked += (asked.empty() ? "" : ", ") + a;
    return Problem{404,
                   "the job did not ask for the pass \"" + std::string(name) +
                       "\" (render.aovs: " + (asked.empty() ? "none" : asked) + ")",
                   std::nullopt};
  }
  if (auto problem = results_not_ready(job)) return *problem;
  return published_result(job, *f);
}

std::variant<std::unique_ptr<FileReader>, Problem> JobService::published_result(const JobRecord& job, JobFile file) {
  if (auto reader = files_.open(job.id, file)) return reader;
  // A run's outputs are published once the store took its end (Scheduler::publish_outputs()); a node that stopped
  // in between left them staged under the run's epoch, which the succeeded job's record names. (Opened again
  // whoever renamed it: the run itself may have done so meanwhile.)
  if (job.state == JobState::kSucceeded) {
    files_.publish_staged(job.id, file, job.epoch);
    if (auto reader = files_.open(job.id, file)) return reader;
  }
  if (job.state == JobState::kCancelled)
    return Problem{404, "the job was cancelled before it finished a pass: it has no partial results", std::nullopt};
  return Problem{404, std::string("the job's ") + job_file_name(file) + " is missing from the data directory",
                 std::nullopt};
}

// ---- changing ---------------------------------------------------------------------------------------------------

std::variant<ActionTaken, Problem> JobService::taken(const std::string& id) {
  auto now = store_.get(id);
  if (!now) return Problem{404, "no such job", std::nullopt};
  return ActionTaken{*now, status(*now)};
}

std::optional<Problem> JobService::queue_full(const std::string& owner) {
  if (options_.max_queued_per_user <= 0) return std::nullopt;
  const int queued = store_.count_by_state(owner).at(JobState::kQueued);
  if (queued < options_.max_queued_per_user) return std::nullopt;
  Problem p{429,
            "you have " + std::to_string(queued) +
                " jobs queued, the most this server allows (--max-queued-per-user); retry later",
            std::nullopt};
  p.retry_after_s = 30;
  return p;
}

std::variant<ActionTaken, Problem> JobService::act(const JobRecord& job, JobAction action) {
  return writing([&]() -> std::variant<ActionTaken, Problem> {
    if (!action_target(action))
      return Problem{500, std::string(job_action_name(action)) + " is not a state change", std::nullopt};
    // Resuming a paused job or requeueing an ended one queues it: the owner's cap holds as for a new job (else pausing
    // at the cap, submitting and resuming would queue one more).
    if (action_target(action) == JobState::kQueued && action_allowed(action, job.state))
      if (auto full = queue_full(job.owner)) return *full;
    switch (change_state(job.id, action)) {
      case Outcome::kDone:
        return taken(job.id);
      case Outcome::kConflict: {
        auto now = store_.get(job.id);
        const JobRecord& latest = now ? *now : job;
        return Problem{409, action_refusal(action, latest.state, latest.input_refused()), std::nullopt};
      }
      case Outcome::kUnknown:
        break;
    }
    return Problem{404, "no such job", std::nullopt};
  });
}

JobService::Outcome JobService::change_state(const std::string& id, JobAction action) {
  switch (action) {
    case JobAction::kCancel:
      return cancel(id);
    case JobAction::kPause:
      return pause(id);
    case JobAction::kResume:
      return resume(id);
    case JobAction::kRequeue:
      return requeue(id);
    case JobAction::kPriority:
    case JobAction::kDelete:
      break;
  }
  return Outcome::kConflict;
}

// The store first, no claim here meanwhile (a queued job stays queued until the change is made): the nodes rendering
// the job, this one included, stop at once (the store's notification; here, Scheduler::stop), and record nothing.
JobService::Outcome JobService::cancel(const std::string& id) {
  {
    const Scheduler::ClaimHold hold = scheduler_.hold_claims();
    auto job = store_.get(id);
    if (!job) return Outcome::kUnknown;
    if (!action_allowed(JobAction::kCancel, job->state)) return Outcome::kConflict;
    log_.add(id, "cancelled by a client");
    if (!results_.record_cancel(*job)) return store_.get(id) ? Outcome::kConflict : Outcome::kUnknown;
    scheduler_.stop(id, Scheduler::StopSignal::kCancel);
  }
  files_.remove(id, JobFile::kCheckpoint);
  log(LogLevel::kInfo, "job cancelled", {{"job", id}});
  publish_state(id);
  return Outcome::kDone;
}

// As cancel(): the store first (a split job's running units go back to the queue with their last checkpoints), then
// the renders here stop (Scheduler::stop: a job rendered whole ends its pass first); the job's checkpoint stays, for
// its resume.
JobService::Outcome JobService::pause(const std::string& id) {
  {
    const Scheduler::ClaimHold hold = scheduler_.hold_claims();
    if (!store_.transition(id, JobState::kPaused, now_ms()))
      return store_.get(id) ? Outcome::kConflict : Outcome::kUnknown;
    scheduler_.stop(id, Scheduler::StopSignal::kPause);
  }
  log(LogLevel::kInfo, "job paused", {{"job", id}});
  log_.add(id, "paused by a client");
  publish_state(id);
  return Outcome::kDone;
}

JobService::Outcome JobService::resume(const std::string& id) {
  if (!store_.transition(id, JobState::kQueued, now_ms(), "", "", JobState::kPaused))
    return store_.get(id) ? Outcome::kConflict : Outcome::kUnknown;
  log(LogLevel::kInfo, "job resumed", {{"job", id}});
  log_.add(id, "resumed by a client: back in the queue");
  publish_state(id);
  scheduler_.wake();
  return Outcome::kDone;
}

// The store first: one that fails (JobStoreError) leaves the job as it was, its preview included, for a retry. No
// claim here meanwhile, so the job is not claimed before the files of its last run are gone.
JobService::Outcome JobService::requeue(const std::string& id) {
  {
    const Scheduler::ClaimHold hold = scheduler_.hold_claims();
    auto job = store_.get(id);
    if (!job) return Outcome::kUnknown;
    if (!action_allowed(JobAction::kRequeue, job->state, job->input_refused())) return Outcome::kConflict;
    if (!store_.transition(id, JobState::kQueued, now_ms(), "", "", job->state)) return Outcome::kConflict;
    // From scratch: nothing of the last run survives.
    for (JobFile f : {JobFile::kCheckpoint, JobFile::kPreviewPng}) files_.remove(id, f);
    for (JobFile f : kResultFiles) files_.remove(id, f);
    files_.remove_units(id);   // a split job's units start over too (the store forgot their checkpoints)
    files_.remove_frames(id);  // and a frame range's frames
  }
  log(LogLevel::kInfo, "job requeued", {{"job", id}});
  log_.add(id, "requeued by a client: the render starts over");
  publish_state(id);
  scheduler_.wake();
  return Outcome::kDone;
}

std::variant<ActionTaken, Problem> JobService::set_priority(const Caller& caller, const JobRecord& job, int priority) {
  return writing([&]() -> std::variant<ActionTaken, Problem> {
    if (priority > options_.max_user_priority && !caller.admin)
      return priority_needs_admin(priority, options_.max_user_priority);
    if (!store_.set_priority(job.id, priority)) {
      auto now = store_.get(job.id);
      if (!now) return Problem{404, "no such job", std::nullopt};
      return Problem{409, action_refusal(JobAction::kPriority, now->state), std::nullopt};
    }
    log(LogLevel::kInfo, "job priority changed", {{"job", job.id}, {"priority", priority}});
    publish_state(job.id);
    return taken(job.id);
  });
}

bool JobService::remove(const std::string& id, std::optional<int64_t> only_finished_before_ms) {
  return writing([&]() -> bool {
    if (!scheduler_.remove(id, only_finished_before_ms)) return false;
    events_.forget(id);
    return true;
  });
}

bool JobService::accepting() const {
  return scheduler_.accepting();
}

bool JobService::store_failing() const {
  return scheduler_.store_failing() || writes_failing_.load();
}

void JobService::publish_state(const std::string& id) {
  auto job = store_.get(id);
  if (!job) return;
  events_.publish(id, job->owner, "state", status(*job).dump(), is_terminal(job->state));
}

}  // namespace tessera::server
