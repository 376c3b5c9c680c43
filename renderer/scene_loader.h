// Reading a JSON scene (format v1, proto/schemas/scene.schema.json) into renderer objects; the render settings' own
// mapping is render_settings.h. Every error is a SceneError carrying the JSON pointer of the offending field.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <stop_token>
#include <vector>

#include <nlohmann/json.hpp>

#include "renderer/render_settings.h"
#include "renderer/scene.h"

namespace tessera {

struct SceneLoadOptions {
  // Folder that file references inside the scene (textures, glTF) resolve against; empty: none allowed.
  std::filesystem::path asset_root;
  size_t max_triangles = 50'000'000;
  size_t max_gltf_vertices = 50'000'000;    // GltfImportOptions::max_vertices
  uint64_t max_gltf_instances = 1'000'000;  // GltfImportOptions::max_instances
  uint64_t max_grid_voxels = 64'000'000;    // GridMediumDesc::max_voxels: voxels of one medium's grid
  // Asked to stop (a daemon shutting down, a job cancelled or paused), load_scene ends soon with LoadStopped.
  std::stop_token stop;
  // false: check the document and make its objects but build no lights or acceleration structure, and check images
  // (textures, environment maps) from their headers without reading their pixels (for validating a job at
  // submission, cheaply); the scene is then not renderable.
  bool build = true;
  // Maps an asset reference of the document ("gltf": "<ref>", an environment map, a medium's grid) to a file; throws
  // SceneError at `pointer` when the reference is unknown. Unset: references are paths relative to asset_root.
  std::function<std::filesystem::path(const std::string& ref, const std::string& pointer)> resolve_asset;
  // Not empty: the scene is a frame of a range of its animation (render.frames, frames.h), which needs a glTF asset
  // with animations; SceneError at this pointer otherwise.
  std::string frames_pointer;
  // Motion blur (render.shutter): the times of the shutter's time steps, in seconds relative to the scene's time
  // (shutter_step_times); an animated glTF asset's moving meshes and camera are posed at each. Empty: no blur.
  std::vector<double> shutter_times;
};

// Builds a scene from the "scene" object of a job. `pointer` is that object's JSON pointer (e.g. "/scene").
// The result is finalized (lights and acceleration structure built).
std::shared_ptr<Scene> load_scene(const nlohmann::json& scene, const std::string& pointer,
                                  const SceneLoadOptions& options);

}  // namespace tessera
