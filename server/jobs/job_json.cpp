#include "server/jobs/job_json.h"

#include <algorithm>

#include "renderer/render_settings.h"
#include "server/base/time_format.h"
#include "server/jobs/render_work.h"

namespace tessera::server {

using nlohmann::json;

namespace {
json time_or_null(const std::optional<int64_t>& ms) {
  return ms ? json(rfc3339_ms(*ms)) : json(nullptr);
}
json text_or_null(const std::string& s) {
  return s.empty() ? json(nullptr) : json(s);
}

// A running unit whose node stopped renewing its lease (it died, or is cut off from the store): no renewal for three
// renewal periods (lease_stall_ms). The unit then waits for its lease to run out before another node takes it over.
bool stalled(const UnitRecord& u, int64_t now) {
  if (!u.running || u.renewed_at_ms <= 0 || u.lease_expires_at_ms <= u.renewed_at_ms) return false;
  return now - u.renewed_at_ms > lease_stall_ms(u.lease_expires_at_ms - u.renewed_at_ms);
}

// The seconds left of a split job whose stalled units wait for their leases: at least, for each, the wait and then
// the rest of its samples at the rate it rendered them (the job's ETA from the store counts a stalled unit as
// rendering on).
std::optional<double> eta_with_stalls(std::optional<double> eta, const std::vector<UnitRecord>& units, int64_t now) {
  for (const UnitRecord& u : units) {
    if (!stalled(u, now)) continue;
    double left = std::max<double>(0.0, static_cast<double>(u.lease_expires_at_ms - now) / 1000.0);
    if (u.samples_done > 0 && u.elapsed_s > 0 && u.samples > u.samples_done)
      left += (u.samples - u.samples_done) * (u.elapsed_s / u.samples_done);
    eta = std::max(eta.value_or(0.0), left);
  }
  return eta;
}

// The units of a split job: how many, done and waiting; the ones running, where (and whether their node stopped
// renewing, with the seconds until another takes them over); and how many each node rendered.
json units_json(const std::vector<UnitRecord>& units, int64_t now) {
  json running = json::array(), nodes = json::object();
  int done = 0, queued = 0;
  for (const UnitRecord& u : units) {
    if (u.done) {
      ++done;
      if (!u.node.empty()) nodes[u.node] = nodes.value(u.node, 0) + 1;
    } else if (u.running) {
      const bool stuck = stalled(u, now);
      running.push_back({{"unit", u.index + 1},
                         {"node", u.node},
                         {"samples_done", u.samples_done},
                         {"samples", u.samples},
                         {"stalled", stuck},
                         {"takeover_in_s",
                          stuck ? json(std::max<double>(0.0, static_cast<double>(u.lease_expires_at_ms - now) / 1000.0))
                                : json(nullptr)}});
    } else {
      ++queued;
    }
  }
  return {{"total", units.size()}, {"done", done}, {"queued", queued}, {"running", running}, {"done_by_node", nodes}};
}

// The frames of a frame range job (render_work.h: renders_frames), bounded whatever the range's length: counts, and
// the frames done, running and failed as ranges of frame numbers [first, last] (every step-th frame between them). A
// range renders its frames in order and a run skips those done before (FrameRangeRender), so the frames done are the
// first ones, as many as its progress counts whole frames of samples: a frame's samples are counted once its files
// are written. A running job renders the next; a failed job failed on it.
json frames_json(const JobRecord& job, const RenderSettings& settings, const JobProgress& p, const std::string& self) {
  const FrameRange& range = *settings.frames;
  const uint64_t total = frame_count(range);
  uint64_t done = settings.spp ? std::min<uint64_t>(p.samples_done / settings.spp, total) : 0;
  if (job.state == JobState::kSucceeded) done = total;
  auto frame = [&](uint64_t i) { return range.start + static_cast<int64_t>(i) * range.step; };
  auto ranges_from = [&](uint64_t first, uint64_t count) {
    json out = json::array();
    if (count > 0) out.push_back({frame(first), frame(first + count - 1)});
    return out;
  };
  const bool next = done < total;
  const bool running = next && job.state == JobState::kRunning;
  const bool failed = next && job.state == JobState::kFailed;
  const std::string pattern = self + "/frames/{frame}/result.";
  json links = json::object();
  if (output_spec_from_text(job.outputs).png) links["result_png"] = pattern + "png";
  if (output_spec_from_text(job.outputs).exr) links["result_exr"] = pattern + "exr";
  return {{"start", range.start},
          {"end", range.end},
          {"step", range.step},
          {"total", total},
          {"done", done},
          {"running", running ? 1 : 0},
          {"failed", failed ? 1 : 0},
          {"done_ranges", ranges_from(0, done)},
          {"running_ranges", ranges_from(done, running ? 1 : 0)},
          {"failed_ranges", ranges_from(done, failed ? 1 : 0)},
          {"latest", done > 0 ? json(frame(done - 1)) : json(nullptr)},
          {"links", links}};
}

}  // namespace

json job_status_json(const JobRecord& job, const std::optional<JobProgress>& live, std::optional<int> queue_position,
                     const std::vector<UnitRecord>& units, int64_t now) {
  JobProgress p = (live && job.state == JobState::kRunning) ? *live : job.progress;
  // A split job's units render side by side on several nodes: the progress the store sums over them is render time,
  // and its wall time runs from the job's start to its end (or now). Its rate, once no unit runs, is the pixel samples
  // its units rendered over that wall time.
  double render_s = p.elapsed_s;
  const bool split = units.size() > 1;
  if (now <= 0) now = now_ms();
  if (split && job.state == JobState::kRunning) p.eta_s = eta_with_stalls(p.eta_s, units, now);
  if (split && job.started_at_ms) {
    const int64_t end = job.finished_at_ms ? *job.finished_at_ms : std::max(now, *job.started_at_ms);
    p.elapsed_s = static_cast<double>(end - *job.started_at_ms) / 1000.0;
    if (p.samples_per_s <= 0 && p.elapsed_s > 0) {
      double pixel_samples = 0;
      for (const UnitRecord& u : units) pixel_samples += u.samples_per_s * u.elapsed_s;
      p.samples_per_s = pixel_samples / p.elapsed_s;
    }
  }
  double fraction = p.samples_total > 0 ? static_cast<double>(p.samples_done) / p.samples_total : 0.0;
  // A render ended by its time limit or noise target is complete with fewer samples than its budget.
  if (job.state == JobState::kSucceeded) fraction = 1.0;
  const std::string self = "/v1/jobs/" + job.id;
  json links = {{"self", self}};
  links["events"] = self + "/events";
  // What the state allows, from the state table: the names, for clients' buttons, and a link for each state change.
  json actions = json::array();
  for (JobAction a : allowed_actions(job.state, job.input_refused())) {
    actions.push_back(job_action_name(a));
    if (action_target(a)) links[job_action_name(a)] = self + "/" + job_action_name(a);
  }
  if (job.state == JobState::kRunning || p.passes > 0) links["preview"] = self + "/preview.png";
  // The record's settings and outputs as the mapping writes them (render_settings.h); a record that cannot be read
  // shows none.
  json outputs = json::array();
  json render = json::object();
  OutputSpec spec;
  try {
    spec = output_spec_from_text(job.outputs);
    outputs = output_spec_to_json(spec);
  } catch (const std::runtime_error&) {
    spec.png = spec.exr = false;
  }
  json frames = nullptr;
  try {
    const RenderSettings settings = render_settings_from_text(job.settings);
    render = render_settings_status_json(settings);
    if (renders_frames(settings)) frames = frames_json(job, settings, p, self);
  } catch (const std::runtime_error&) {
  }
  // A job cancelled after a pass has the image of its last complete pass as its (partial) results. A frame range's
  // results are its frames' (frames.links).
  if (frames.is_null() &&
      (job.state == JobState::kSucceeded || (job.state == JobState::kCancelled && p.samples_done > 0))) {
    if (spec.png) links["result_png"] = self + "/result.png";
    if (spec.exr) links["result_exr"] = self + "/result.exr";
    // Each render pass's PNG, by the pass's name.
    if (render.contains("aovs")) {
      json passes = json::object();
      for (const json& name : render["aovs"])
        passes[name.get<std::string>()] = self + "/aovs/" + name.get<std::string>() + ".png";
      links["aovs"] = std::move(passes);
    }
  }
  json warnings = json::parse(job.warnings.empty() ? "[]" : job.warnings, nullptr, false);
  if (!warnings.is_array()) warnings = json::array();
  // "stopped" is how a render ends when the daemon stops or the job is paused; such a job is not finished and shows
  // no stop reason. A failed job shows its error instead (and its actions whether it may run again).
  const std::string stop_reason = job.stop_reason == "stopped" || job.state == JobState::kFailed ? "" : job.stop_reason;
  return {
      {"id", job.id},
      {"name", job.name},
      {"kind", job.kind},
      {"state", job_state_name(job.state)},
      {"priority", job.priority},
      {"queue_position", job.state == JobState::kQueued && queue_position ? json(*queue_position) : json(nullptr)},
      {"owner", text_or_null(job.owner)},
      {"warnings", warnings},
      {"created_at", rfc3339_ms(job.created_at_ms)},
      {"started_at", time_or_null(job.started_at_ms)},
      {"finished_at", time_or_null(job.finished_at_ms)},
      {"progress",
       {{"passes", p.passes},
        {"samples_done", p.samples_done},
        {"samples_total", p.samples_total},
        {"fraction", fraction},
        {"elapsed_s", p.elapsed_s},
        {"render_s", render_s},
        {"eta_s", p.eta_s ? json(*p.eta_s) : json(nullptr)},
        {"samples_per_s", p.samples_per_s}}},
      {"units", split ? units_json(units, now) : json(nullptr)},
      {"frames", frames},
      {"stop_reason", text_or_null(stop_reason)},
      {"error", text_or_null(job.error)},
      {"outputs", outputs},
      {"render", render},
      {"actions", actions},
      {"links", links},
  };
}

}  // namespace tessera::server
