// glTF 2.0 import through tinygltf: the node hierarchy, meshes, cameras, materials (onto the gltf_pbr model),
// KHR_lights_punctual, with every external reference confined to the asset's own folder.
#pragma once

#include <filesystem>
#include <map>
#include <stop_token>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "renderer/scene.h"

namespace tessera {

struct GltfCamera {
  std::string name;
  CameraDesc desc;
  float aspect_ratio = 0;  // glTF's aspectRatio, 0 when absent
  // Its poses at the shutter's time steps (GltfImportOptions::shutter_times) when it moves over them; else empty.
  std::vector<CameraDesc> motion;
};

struct GltfImport {
  std::vector<GltfCamera> cameras;    // in glTF camera order... one per node that carries a camera
  std::vector<PunctualLight> lights;  // KHR_lights_punctual instances, in world space
  std::vector<std::string> warnings;
  Bounds bounds;
};

struct GltfImportOptions {
  // Materials of the job that replace glTF materials of the same name (already created).
  std::map<std::string, uint32_t> material_overrides;
  size_t max_triangles = 50'000'000;
  // Vertices of every primitive built, counted from each POSITION accessor's count before any is read.
  size_t max_vertices = 50'000'000;
  // Bytes the import may make that its files do not hold: accessors without a buffer view (which glTF fills with
  // zeros), and Draco and meshopt streams as decoded. Each is counted before it is allocated, against the least of
  // this and 256 MiB + 64 times the bytes of the asset's buffers, so that a file of a few hundred bytes cannot
  // declare gigabytes.
  size_t max_decoded_bytes = size_t{1} << 31;
  size_t max_texture_pixels = 64u << 20;
  // Node instances: every path from a scene's roots to a node counts, since nodes may share children (a chain where
  // each node lists the next four times is 4^n instances of a few nodes). Above it, SceneError naming the limit.
  uint64_t max_instances = 1'000'000;
  // Asked to stop (shutdown, cancel), the import ends soon with LoadStopped.
  std::stop_token stop;
  // The KHR_materials_variants variant to render, by name: each primitive takes the material its mapping gives that
  // variant (the default material where none does). Empty: the default materials. An unknown name is a SceneError at
  // `variant_pointer` naming the asset's variants.
  std::string variant;
  std::string variant_pointer;
  // Animation (glTF 2.0, 3.11): with `animate`, the nodes are posed by one of the asset's animations at `time`
  // seconds: the one named `animation_name`, else the one at `animation_index`, else the first (an asset without
  // animations is then posed as stated). Without it, the nodes' own transforms and the meshes' default weights (the
  // static pose). An animation the asset does not have is a SceneError at `animation_pointer`.
  bool animate = false;
  double time = 0;
  std::string animation_name;
  int animation_index = -1;
  std::string animation_pointer;
  // Not empty: a frame range of the animation is rendered (frames.h), and an asset without animations is a SceneError
  // at this pointer rather than the static pose with a warning.
  std::string frames_pointer;
  // Motion blur: the times of a shutter's time steps, in seconds relative to `time` (frames.h, shutter_step_times).
  // With an animation applied, the nodes are posed at each as well, and every mesh and camera that moves over them
  // gets its poses at them (Mesh::motion_positions, GltfCamera::motion); meshes are then never instanced (each moving
  // copy has vertices of its own). Emissive meshes keep the frame's pose: the lights are sampled where they are hit.
  std::vector<double> shutter_times;
  // Images are checked from their headers (they open, within max_texture_pixels) and stand in as 1x1 white: for a
  // scene that is checked, not rendered.
  bool headers_only = false;
};

// Appends the default scene of the glTF file `path` (.glb or .gltf) to `scene`. URIs inside may name only files in
// the folder of `path` or its subfolders (proto/asset_path.h), or be data: URIs. Throws SceneError at `pointer` naming
// what is wrong, LoadStopped when options.stop is asked to stop.
GltfImport import_gltf(const std::filesystem::path& path, const std::string& pointer, Scene& scene,
                       const GltfImportOptions& options);

}  // namespace tessera
