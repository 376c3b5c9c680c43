#include "renderer/job.h"

#include <cctype>

#include "renderer/frames.h"
#include "renderer/scene_error.h"

namespace tessera {

using nlohmann::json;

namespace {

std::string kind_of(const json& job) {
  if (!job.is_object()) throw SceneError("", "the job must be a JSON object");
  auto it = job.find("kind");
  if (it == job.end()) return "scene";
  if (!it->is_string() || (*it != "scene" && *it != "material"))
    throw SceneError("/kind", "must be \"scene\" or \"material\"");
  return it->get<std::string>();
}

}  // namespace

RenderJob load_job(const json& job, const JobLoadOptions& options) {
  const std::string kind = kind_of(job);
  RenderJob out;
  if (auto outputs = job.find("outputs"); outputs != job.end())
    out.outputs = output_spec_from_json(*outputs, "/outputs");
  auto render = job.find("render");
  const json given = render == job.end() ? json() : *render;
  // A material preview samples adaptively and is denoised unless its document says otherwise.
  out.settings =
      render_settings_from_json(kind == "material" ? with_preview_defaults(given) : given, "/render", options.limits);
  out.scene = load_job_scene(job, out.settings, options.scene);
  return out;
}

std::shared_ptr<Scene> load_job_scene(const json& job, const RenderSettings& settings,
                                      const SceneLoadOptions& options) {
  return load_frame_scene(job, settings, settings.frames ? settings.frames->start : 0, options);
}

std::shared_ptr<Scene> load_frame_scene(const json& job, const RenderSettings& settings, int64_t frame,
                                        const SceneLoadOptions& options) {
  std::shared_ptr<Scene> scene;
  const std::string kind = kind_of(job);
  SceneLoadOptions scene_options = options;
  if (settings.shutter) scene_options.shutter_times = shutter_step_times(*settings.shutter, settings.fps);
  if (settings.frames) {
    if (kind != "scene") throw SceneError("/render/frames", "a material job has no animation to render frames of");
    const auto it = job.find("scene");
    if (it != job.end() && it->is_object() && it->contains("time"))
      throw SceneError("/scene/time",
                       "a frame range gives each frame its time (frame / render.fps): leave scene.time out, and shift "
                       "the frames' times with scene.time_offset");
  } else if (kind == "scene") {
    const auto it = job.find("scene");
    if (it != job.end() && it->is_object() && it->contains("time_offset"))
      throw SceneError("/scene/time_offset",
                       "shifts the times of a frame range (render.frames); a still is posed at scene.time");
  }
  if (kind == "material") {
    // The stage scene names the subjects "subject" (one material) or "subject0".."subject15" (a row); errors found
    // in it are reported at the job's own fields: /material/... or /materials/<i>/...
    try {
      scene = load_scene(material_stage_scene(job, settings.width, settings.height), "", scene_options);
    } catch (const SceneError& e) {
      const std::string& p = e.pointer();
      const std::string row = "/materials/subject";
      std::string mapped = p;
      if (p.rfind(row, 0) == 0) {
        size_t digits = row.size();
        while (digits < p.size() && std::isdigit(static_cast<unsigned char>(p[digits]))) ++digits;
        mapped = digits > row.size() ? "/materials/" + p.substr(row.size(), digits - row.size()) + p.substr(digits)
                                     : "/material" + p.substr(row.size());
      }
      throw SceneError(mapped, e.what());
    }
  } else {
    auto it = job.find("scene");
    if (it == job.end()) throw SceneError("/scene", "a scene job needs a \"scene\"");
    if (settings.frames) {
      SceneLoadOptions frame_options = scene_options;
      frame_options.frames_pointer = "/render/frames";
      scene = load_scene(frame_scene(*it, frame, settings.fps), "/scene", frame_options);
    } else {
      scene = load_scene(*it, "/scene", scene_options);
    }
  }
  const Camera camera(scene->camera, settings.width, settings.height);
  const std::string problem = integrator_camera_problem(settings.integrator.name, camera);
  if (!problem.empty()) throw SceneError("/render/integrator", problem);
  return scene;
}

json material_stage_scene(const json& job, int width_px, int height_px) {
  // The built-in preview stage: each material on a sphere (curvature shows every angle of incidence at once; the
  // sphere's tangent runs along its parallels, so anisotropic highlights stretch visibly) standing on a checker
  // floor that shows through transmissive materials and in reflective ones, under a soft sky-coloured environment
  // and one large key light up front on the left. {"material": m} renders one sphere, {"materials": [m, ...]} a row
  // of them, left to right; the camera frames the row for the job's aspect ratio. Everything is fixed: the stage
  // is deterministic.
  std::vector<json> subjects;
  auto one = job.find("material");
  auto many = job.find("materials");
  if (one != job.end() && many != job.end())
    throw SceneError("/materials", "a material job has either \"material\" or \"materials\", not both");
  if (one != job.end()) {
    subjects.push_back(*one);
  } else if (many != job.end()) {
    if (!many->is_array() || many->empty() || many->size() > 16)
      throw SceneError("/materials", "must be an array of 1 to 16 materials");
    for (const json& m : *many) subjects.push_back(m);
  } else {
    throw SceneError("/material", "a material job needs a \"material\" (or \"materials\" for a row)");
  }

  const int n = static_cast<int>(subjects.size());
  const double spacing = 2.5;                       // sphere centres, radius 1
  const double row_half = 0.5 * (n - 1) * spacing;  // half the distance between the outer centres
  json scene;
  json materials = json::object();
  json objects = json::array();
  for (int i = 0; i < n; ++i) {
    const std::string name = n == 1 ? "subject" : "subject" + std::to_string(i);
    materials[name] = subjects[i];
    objects.push_back(
        {{"shape", "sphere"}, {"center", {-row_half + i * spacing, 1, 0}}, {"radius", 1}, {"material", name}});
  }
  // Floor: 1-unit checker squares around the row.
  const double floor_half = std::max(12.0, row_half + 12.0);
  const double squares = 2 * floor_half;
  materials["stage_floor"] = {
      {"type", "lambert"},
      {"albedo", {{"checker", {{"a", {0.62, 0.62, 0.6}}, {"b", {0.18, 0.18, 0.19}}, {"scale", squares}}}}}};
  objects.push_back({{"shape", "rectangle"},
                     {"corner", {-floor_half, 0, floor_half}},
                     {"edge1", {2 * floor_half, 0, 0}},
                     {"edge2", {0, 0, -2 * floor_half}},
                     {"material", "stage_floor"}});
  // Key light: a bright sphere up front on the left, big enough for soft shadows and a visible highlight shape.
  materials["stage_key"] = {{"type", "emission"}, {"radiance", {14, 13.5, 12.5}}};
  objects.push_back(
      {{"shape", "sphere"}, {"center", {-row_half - 4.0, 6.5, 5.0}}, {"radius", 1.2}, {"material", "stage_key"}});
  scene["materials"] = materials;
  scene["objects"] = objects;
  scene["environment"] = {{"color", {0.42, 0.46, 0.52}}};

  // Camera: slightly above the spheres' centres, looking a little down; far enough back that the row (with a
  // margin) fits the horizontal and vertical field of view at the job's aspect ratio.
  const double aspect = static_cast<double>(width_px) / height_px;
  const double fov_deg = 30;
  const double tan_half_v = std::tan(fov_deg * kPi / 360.0);
  const double tan_half_h = tan_half_v * aspect;
  const double need_h = (row_half + 1.35) / tan_half_h;  // horizontal extent with a margin
  const double need_v = 1.5 / tan_half_v;                // the sphere's height with floor around it
  const double dist = std::max(need_h, need_v);
  scene["camera"] = {{"from", {0, 1.0 + 0.32 * dist, dist}}, {"to", {0, 0.85, 0}}, {"fov_deg", fov_deg}};
  return scene;
}

}  // namespace tessera
