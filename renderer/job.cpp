#include "renderer/job.h"

#include "renderer/scene_error.h"

namespace tessera {

using nlohmann::json;

namespace {

void read_outputs(const json& job, RenderJob* out) {
  auto it = job.find("outputs");
  if (it == job.end()) return;
  if (!it->is_array() || it->empty()) throw SceneError("/outputs", "must be a non-empty array of \"png\" and \"exr\"");
  out->want_png = out->want_exr = false;
  for (size_t i = 0; i < it->size(); ++i) {
    const json& o = (*it)[i];
    if (o == "png") out->want_png = true;
    else if (o == "exr") out->want_exr = true;
    else throw SceneError("/outputs/" + std::to_string(i), "must be \"png\" or \"exr\"");
  }
}

std::string kind_of(const json& job) {
  if (!job.is_object()) throw SceneError("", "the job must be a JSON object");
  auto it = job.find("kind");
  if (it == job.end()) return "scene";
  if (!it->is_string() || (*it != "scene" && *it != "material"))
    throw SceneError("/kind", "must be \"scene\" or \"material\"");
  return it->get<std::string>();
}

}  // namespace

RenderSettings load_job_settings(const json& job, const JobLoadOptions& options) {
  kind_of(job);
  auto it = job.find("render");
  RenderJob tmp;
  read_outputs(job, &tmp);
  return parse_render_settings(it == job.end() ? json() : *it, "/render", options.limits);
}

RenderJob load_job(const json& job, const JobLoadOptions& options) {
  RenderJob out;
  out.settings = load_job_settings(job, options);
  read_outputs(job, &out);
  if (kind_of(job) == "material") {
    out.scene = load_scene(material_stage_scene(job), "/material", options.scene);
  } else {
    auto it = job.find("scene");
    if (it == job.end()) throw SceneError("/scene", "a scene job needs a \"scene\"");
    out.scene = load_scene(*it, "/scene", options.scene);
  }
  return out;
}

json material_stage_scene(const json& job) {
  // The built-in stage: the material on a sphere over a checker floor, under a soft environment and one key light.
  // (The materials work replaces this with the full stage; kept minimal here.)
  auto it = job.find("material");
  if (it == job.end()) throw SceneError("/material", "a material job needs a \"material\"");
  json scene;
  scene["materials"] = {{"subject", *it},
                        {"floor", {{"type", "lambert"}, {"albedo", {0.5, 0.5, 0.5}}}},
                        {"key", {{"type", "emission"}, {"radiance", {20, 20, 20}}}}};
  scene["objects"] = json::array({
      {{"shape", "sphere"}, {"center", {0, 1, 0}}, {"radius", 1}, {"material", "subject"}},
      {{"shape", "rectangle"}, {"corner", {-10, 0, 10}}, {"edge1", {20, 0, 0}}, {"edge2", {0, 0, -20}},
       {"material", "floor"}},
      {{"shape", "sphere"}, {"center", {4, 6, 4}}, {"radius", 0.6}, {"material", "key"}},
  });
  scene["camera"] = {{"from", {0, 2, 6}}, {"to", {0, 0.9, 0}}, {"fov_deg", 35}};
  scene["environment"] = {{"color", {0.3, 0.35, 0.4}}};
  return scene;
}

}  // namespace tessera
