#include "server/submission.h"

#include <algorithm>
#include <cctype>

#include "proto/contract.h"
#include "renderer/job.h"
#include "renderer/scene.h"
#include "renderer/scene_error.h"

namespace tessera::server {

using nlohmann::json;

std::string media_type(std::string_view content_type) {
  std::string_view t = content_type.substr(0, content_type.find(';'));
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.front()))) t.remove_prefix(1);
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.back()))) t.remove_suffix(1);
  std::string out(t);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return std::tolower(c); });
  return out;
}

json render_settings_json(const RenderSettings& s) {
  return {{"width", s.width},
          {"height", s.height},
          {"spp", s.spp},
          {"max_depth", s.integrator.max_depth},
          {"integrator", s.integrator.name},
          {"estimator", estimator_name(s.integrator.estimator)},
          {"seed", s.seed},
          {"sampler", s.sampler == SamplerKind::kSobol ? "sobol" : "independent"},
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
  if (proto::json_nesting_depth(body) > static_cast<size_t>(limits.max_depth))
    return Problem{422, "the document is nested deeper than " + std::to_string(limits.max_depth) + " levels", ""};

  json document;
  try {
    document = json::parse(body);
  } catch (const json::parse_error& e) {
    return Problem{400, std::string("the body is not valid JSON: ") + e.what(), ""};
  }
  return check_job_document(std::move(document), limits);
}

std::variant<AcceptedJob, Problem> check_job_document(json document, const SubmissionLimits& limits) {
  AcceptedJob job;
  job.document = std::move(document);
  if (auto error = proto::contract_schemas().validate(job.document, "job.schema.json", limits.max_depth))
    return Problem{422, error->message, error->pointer};

  JobLoadOptions options;
  options.scene.build = false;  // names, indices and assets are checked; no BVH is built at submission
  options.scene.resolve_asset = limits.resolve_asset;
  options.limits = limits.render;
  RenderJob render_job;
  try {
    render_job = load_job(job.document, options);
  } catch (const SceneError& e) {
    return Problem{422, e.what(), e.pointer()};
  }
  const RenderSettings& s = render_job.settings;
  const double work = static_cast<double>(s.width) * s.height * s.spp * std::max(1, s.integrator.max_depth);
  if (limits.max_work > 0 && work > limits.max_work)
    return Problem{422,
                   "width x height x spp x max_depth is " + std::to_string(static_cast<long long>(work)) +
                       ", above this server's limit of " + std::to_string(static_cast<long long>(limits.max_work)) +
                       " (--max-work); lower the resolution, spp or max_depth",
                   "/render"};
  if (render_job.scene) job.warnings = render_job.scene->warnings;
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
