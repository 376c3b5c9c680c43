#include "server/job_json.h"

#include "server/time_format.h"

namespace tessera::server {

using nlohmann::json;

namespace {
json time_or_null(const std::optional<int64_t>& ms) {
  return ms ? json(rfc3339_ms(*ms)) : json(nullptr);
}
json text_or_null(const std::string& s) {
  return s.empty() ? json(nullptr) : json(s);
}
}  // namespace

json job_status_json(const JobRecord& job, const std::optional<JobProgress>& live, std::optional<int> queue_position) {
  const JobProgress& p = (live && job.state == JobState::kRunning) ? *live : job.progress;
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
  json outputs = json::parse(job.outputs, nullptr, false);
  if (!outputs.is_array()) outputs = json::array();
  // A job cancelled after a pass has the image of its last complete pass as its (partial) results.
  if (job.state == JobState::kSucceeded || (job.state == JobState::kCancelled && p.samples_done > 0)) {
    for (const json& o : outputs) {
      if (o == "png") links["result_png"] = self + "/result.png";
      if (o == "exr") links["result_exr"] = self + "/result.exr";
    }
  }
  json render = json::parse(job.settings, nullptr, false);
  if (!render.is_object()) render = json::object();
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
        {"eta_s", p.eta_s ? json(*p.eta_s) : json(nullptr)},
        {"samples_per_s", p.samples_per_s}}},
      {"stop_reason", text_or_null(stop_reason)},
      {"error", text_or_null(job.error)},
      {"outputs", outputs},
      {"render", render},
      {"actions", actions},
      {"links", links},
  };
}

}  // namespace tessera::server
