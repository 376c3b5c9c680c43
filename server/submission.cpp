#include "server/submission.h"

#include <algorithm>
#include <cctype>

#include "renderer/job.h"
#include "renderer/scene_error.h"
#include "server/contract.h"

namespace tessera::server {

using nlohmann::json;

namespace {

std::string media_type(std::string_view content_type) {
  std::string_view t = content_type.substr(0, content_type.find(';'));
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.front()))) t.remove_prefix(1);
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.back()))) t.remove_suffix(1);
  std::string out(t);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return std::tolower(c); });
  return out;
}

}  // namespace

json render_settings_json(const RenderSettings& s) {
  return {{"width", s.width},
          {"height", s.height},
          {"spp", s.spp},
          {"max_depth", s.integrator.max_depth},
          {"estimator", estimator_name(s.integrator.estimator)},
          {"seed", s.seed},
          {"time_limit_s", s.time_limit_s},
          {"noise_target", s.noise_target},
          {"exposure_ev", s.display.exposure_ev},
          {"tonemap", tonemap_name(s.display.tonemap)},
          {"exr_precision", s.exr_half ? "half" : "float"}};
}

std::variant<AcceptedJob, Problem> check_submission(std::string_view content_type, std::string_view body,
                                                    const SubmissionLimits& limits) {
  if (media_type(content_type) != "application/json")
    return Problem{415, "a job is submitted as application/json, not \"" + std::string(content_type) + "\"",
                   std::nullopt};
  if (body.find_first_not_of(" \t\r\n") == std::string_view::npos)
    return Problem{400, "the body is empty; expected a job document (JSON)", ""};
  if (json_nesting_depth(body) > static_cast<size_t>(limits.max_depth))
    return Problem{422, "the document is nested deeper than " + std::to_string(limits.max_depth) + " levels", ""};

  AcceptedJob job;
  try {
    job.document = json::parse(body);
  } catch (const json::parse_error& e) {
    return Problem{400, std::string("the body is not valid JSON: ") + e.what(), ""};
  }
  if (auto error = contract_schemas().validate(job.document, "job.schema.json", limits.max_depth))
    return Problem{422, error->message, error->pointer};

  JobLoadOptions options;
  options.scene.build = false;  // names and indices are checked; no BVH is built at submission
  options.limits = limits.render;
  RenderJob render_job;
  try {
    render_job = load_job(job.document, options);
  } catch (const SceneError& e) {
    return Problem{422, e.what(), e.pointer()};
  }
  job.kind = job.document.value("kind", "scene");
  job.priority = job.document.value("priority", 0);
  job.settings = render_settings_json(render_job.settings);
  job.outputs = json::array();
  if (render_job.want_png) job.outputs.push_back("png");
  if (render_job.want_exr) job.outputs.push_back("exr");
  job.spp = render_job.settings.spp;
  return job;
}

}  // namespace tessera::server
