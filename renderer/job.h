// A job document ({"kind": "scene" | "material", ...}, proto/schemas/job.schema.json) turned into what a render
// session needs. Validation against the schema happens before (server/ or the command line); this adds the checks
// a schema cannot express (material names that exist, geometry that makes sense) and raises SceneError naming the
// field.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "renderer/scene_loader.h"

namespace tessera {

struct RenderJob {
  std::shared_ptr<Scene> scene;
  RenderSettings settings;
  bool want_png = true;
  bool want_exr = true;
};

struct JobLoadOptions {
  SceneLoadOptions scene;
  RenderLimits limits;
};

// Reads only "render" and "outputs": cheap, for validating a job at submission without building its scene.
RenderSettings load_job_settings(const nlohmann::json& job, const JobLoadOptions& options);
// Reads the whole job and builds its scene (BVH included).
RenderJob load_job(const nlohmann::json& job, const JobLoadOptions& options);

// Builds the scene document of a material job: the material(s) on the built-in preview stage.
nlohmann::json material_stage_scene(const nlohmann::json& job);

}  // namespace tessera
