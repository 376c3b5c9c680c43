// Reading documents into renderer objects: a JSON scene (format v1, proto/schemas/scene.schema.json) and render
// settings. Every error is a SceneError carrying the JSON pointer of the offending field.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <stop_token>

#include <nlohmann/json.hpp>

#include "renderer/scene.h"
#include "renderer/session.h"

namespace tessera {

struct SceneLoadOptions {
  // Folder that file references inside the scene (textures, glTF) resolve against; empty: none allowed.
  std::filesystem::path asset_root;
  size_t max_triangles = 50'000'000;
  uint64_t max_gltf_instances = 1'000'000;  // GltfImportOptions::max_instances
  // Asked to stop (a daemon shutting down, a job cancelled or paused), load_scene ends soon with LoadStopped.
  std::stop_token stop;
  // false: check the document and make its objects but build no lights or acceleration structure, and check images
  // (textures, environment maps) from their headers without reading their pixels (for validating a job at
  // submission, cheaply); the scene is then not renderable.
  bool build = true;
  // Maps an asset reference of the document ("gltf": "<ref>", an environment map) to a file; throws SceneError at
  // `pointer` when the reference is unknown. Unset: references are paths relative to asset_root.
  std::function<std::filesystem::path(const std::string& ref, const std::string& pointer)> resolve_asset;
};

// Builds a scene from the "scene" object of a job. `pointer` is that object's JSON pointer (e.g. "/scene").
// The result is finalized (lights and acceleration structure built).
std::shared_ptr<Scene> load_scene(const nlohmann::json& scene, const std::string& pointer,
                                  const SceneLoadOptions& options);

// render.spp when the job does not say (the contract's default).
constexpr uint32_t kDefaultSpp = 64;

struct RenderLimits {
  int max_width = 8192;
  int max_height = 8192;
  uint32_t max_spp = 1u << 16;
  int max_depth = 1024;
};

// Reads the "render" object of a job (defaults for absent keys). `pointer` is its JSON pointer.
RenderSettings parse_render_settings(const nlohmann::json& render, const std::string& pointer,
                                     const RenderLimits& limits);

}  // namespace tessera
