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
#include "renderer/session.h"

namespace tessera {

struct RenderJob {
  std::shared_ptr<Scene> scene;
  RenderSettings settings;
  OutputSpec outputs;
};

struct JobLoadOptions {
  SceneLoadOptions scene;
  RenderLimits limits;
};

// Reads the whole job ("render" and "outputs" through render_settings.h; a material job's "render" with the preview's
// defaults, with_preview_defaults) and builds its scene (BVH included).
RenderJob load_job(const nlohmann::json& job, const JobLoadOptions& options);
// Builds the scene of a job whose settings were read before (a job record's): its "scene", or its material(s) on the
// preview stage, framed for the settings' image size; checks that the settings' integrator can render it. A job with
// a frame range (settings.frames) gets the scene of its first frame: a range of one frame is the still at its time.
std::shared_ptr<Scene> load_job_scene(const nlohmann::json& job, const RenderSettings& settings,
                                      const SceneLoadOptions& options);
// The scene of frame `frame` of a job with a frame range (frames.h): the job's scene at the frame's time, exactly the
// still a job with scene.time at that time renders. A frame range needs a scene job of a glTF asset with animations,
// without scene.time (each frame has its own): SceneError naming the field otherwise. Without settings.frames, the
// job's scene as load_job_scene builds it.
std::shared_ptr<Scene> load_frame_scene(const nlohmann::json& job, const RenderSettings& settings, int64_t frame,
                                        const SceneLoadOptions& options);

// Builds the scene document of a material job: the material(s) on the built-in preview stage, framed for an image of
// `width` x `height` pixels.
nlohmann::json material_stage_scene(const nlohmann::json& job, int width, int height);

}  // namespace tessera
