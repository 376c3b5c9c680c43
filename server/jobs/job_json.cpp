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

// The frames of a frame range job (work_units.h: renders_frames), bounded whatever the range's length: counts, and the
// frames done, running and failed as ranges of frame numbers [first, last] (every step-th frame between them), at most
// kMaxFrameRanges of each. A range of units has each unit's frames in its unit's state (a unit still running when its
// job failed is the one that failed it). A range rendered whole renders its frames in order and a run skips those
// done before, so the frames done are the first ones, as many as its progress counts whole frames of samples; a
// running job renders the next, and a failed job failed on it.
constexpr size_t kMaxFrameRanges = 64;

json frames_json(const JobRecord& job, const RenderSettings& settings, const JobProgress& p,
                 const std::vector<UnitRecord>& units, const std::string& self) {
  const FrameRange& range = *settings.frames;
  const uint64_t total = frame_count(range);
  enum Kind { kDone, kRunning, kFailed, kWaiting };
  struct Segment {
    Kind kind;
    uint64_t first, count;  // frame indices in the range
  };
  std::vector<Segment> segments;
  const bool failed_job = job.state == JobState::kFailed;
  if (units.empty()) {
    uint64_t done = settings.spp ? std::min<uint64_t>(p.samples_done / settings.spp, total) : 0;
    if (job.state == JobState::kSucceeded) done = total;
    segments.push_back({kDone, 0, done});
    if (done < total && (job.state == JobState::kRunning || failed_job))
      segments.push_back({failed_job ? kFailed : kRunning, done, 1});
  } else {
    const uint64_t chunk = static_cast<uint64_t>(std::max<int64_t>(range.chunk, 1));
    for (const UnitRecord& u : units) {
      const Kind kind = u.done ? kDone : u.running ? (failed_job ? kFailed : kRunning) : kWaiting;
      const uint64_t first = static_cast<uint64_t>(u.index) * chunk;
      if (first < total) segments.push_back({kind, first, std::min(chunk, total - first)});
    }
  }
  uint64_t counts[4] = {0, 0, 0, 0};
  json lists[3] = {json::array(), json::array(), json::array()};
  bool truncated = false;
  auto frame = [&](uint64_t i) { return range.start + static_cast<int64_t>(i) * range.step; };
  std::optional<uint64_t> last_done;
  for (size_t i = 0; i < segments.size(); ++i) {
    const Segment& seg = segments[i];
    counts[seg.kind] += seg.count;
    if (seg.kind == kWaiting || seg.count == 0) continue;
    if (seg.kind == kDone) last_done = std::max(last_done.value_or(0), seg.first + seg.count - 1);
    json& list = lists[seg.kind];
    // Consecutive segments of one kind make one range.
    if (!list.empty() && i > 0 && segments[i - 1].kind == seg.kind &&
        segments[i - 1].first + segments[i - 1].count == seg.first &&
        list.back()[1] == frame(segments[i - 1].first + segments[i - 1].count - 1)) {
      list.back()[1] = frame(seg.first + seg.count - 1);
    } else if (list.size() < kMaxFrameRanges) {
      list.push_back({frame(seg.first), frame(seg.first + seg.count - 1)});
    } else {
      truncated = true;
    }
  }
  const std::string pattern = self + "/frames/{frame}/result.";
  json links = json::object();
  const OutputSpec spec = output_spec_from_text(job.outputs);
  if (spec.png) links["result_png"] = pattern + "png";
  if (spec.exr) links["result_exr"] = pattern + "exr";
  return {{"start", range.start},
          {"end", range.end},
          {"step", range.step},
          {"chunk", range.chunk},
          {"total", total},
          {"done", counts[kDone]},
          {"running", counts[kRunning]},
          {"failed", counts[kFailed]},
          {"done_ranges", lists[kDone]},
          {"running_ranges", lists[kRunning]},
          {"failed_ranges", lists[kFailed]},
          {"ranges_truncated", truncated},
          {"last_done", last_done ? json(frame(*last_done)) : json(nullptr)},
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
    if (renders_frames(settings)) frames = frames_json(job, settings, p, units, self);
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
