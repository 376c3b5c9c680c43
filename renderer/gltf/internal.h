// The parts of the glTF importer (import_gltf, renderer/gltf/loader.h), one file each by concern: reading the asset
// (gltf/files.cpp: container, confined URIs, extensions, images), materials (gltf/materials.cpp), animations
// (gltf/animation.cpp: keyframes, interpolation, poses), meshes (gltf/meshes.cpp: accessors, morph targets, skins)
// and nodes (gltf/nodes.cpp: the scene graph, instancing, cameras, lights). Internal to the renderer.
#pragma once

#include <tiny_gltf.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "renderer/gltf/loader.h"
#include "renderer/math.h"
#include "renderer/scene.h"
#include "renderer/scene_error.h"
#include "renderer/texture.h"

namespace tessera::gltf {

using nlohmann::json;

// What an import makes that its files do not hold (GltfImportOptions::max_decoded_bytes), counted before it is made.
class DecodeBudget {
 public:
  // What an asset may make: `allowance`, at most `cap` (GltfImportOptions::max_decoded_bytes).
  DecodeBudget(size_t allowance, size_t cap, std::string pointer)
      : allowance_(std::min(allowance, cap)), cap_(cap), pointer_(std::move(pointer)) {}
  // Counts `bytes` that `what` makes; SceneError naming it and the allowance once the import's total passes it.
  void take(size_t bytes, const std::string& what);

 private:
  size_t allowance_;
  size_t cap_;
  size_t used_ = 0;
  std::string pointer_;
};

// One import's shared state: where it reads from, what it adds to, and what it counts against the limits.
struct Import {
  Import(const std::filesystem::path& path_, const std::string& pointer_, Scene& scene_,
         const GltfImportOptions& options_, GltfImport& result_)
      : path(path_), pointer(pointer_), scene(scene_), options(options_), result(result_) {}
  const std::filesystem::path& path;
  const std::string& pointer;
  Scene& scene;
  const GltfImportOptions& options;
  GltfImport& result;
  json doc;  // the asset's JSON, with its URIs as tinygltf was given them
  tinygltf::Model model;
  size_t triangles = 0;             // in the scene so far, instances counted
  size_t vertices = 0;              // of the primitives built so far
  DecodeBudget decoded{0, 0, ""};   // set by read_asset, once the buffers' sizes are known
  std::string tinygltf_warnings;    // what tinygltf said while parsing, reported last
  std::set<int> meshopt_fallbacks;  // buffers EXT_meshopt_compression marks as fallbacks (not read)

  void check_stop() const {
    if (options.stop.stop_requested()) throw LoadStopped();
  }
  [[noreturn]] void fail(const std::string& what) const { throw SceneError(pointer, what); }
  void warn(std::string what) { result.warnings.push_back(std::move(what)); }
  // Counts the vertices of a primitive about to be built; throws past options.max_vertices.
  void count_vertices(size_t count) {
    vertices += count;
    if (vertices > options.max_vertices)
      fail("the asset exceeds the limit of " + std::to_string(options.max_vertices) + " vertices");
  }
  // Throws once the scene holds more triangles than the limit.
  void check_triangles() const {
    if (triangles > options.max_triangles)
      fail("the asset exceeds the limit of " + std::to_string(options.max_triangles) + " triangles");
  }
};

// An object's "extensions" as stored by tinygltf (its original JSON text), or {} when absent or unreadable.
json parse_extensions(const std::string& text);

// ---- gltf/files.cpp ----

// Reads the asset at import.path into import.doc and import.model: the container's framing, every URI confined to
// the asset's folder (proto/asset_path.h), the required extensions supported (unsupported used ones are warnings),
// images kept encoded. Throws SceneError.
void read_asset(Import& import);

// Decodes the model's images (in parallel; headers only with options.headers_only) as "image<i>" for materials.
std::map<std::string, std::shared_ptr<const ImagePixels>> decode_images(Import& import);

// ---- gltf/compression.cpp ----

// Decodes EXT_meshopt_compression buffer views and KHR_draco_mesh_compression primitives in import.model into
// buffers of their own, which the views and the primitives' accessors then read. Throws SceneError.
void decode_compressed_geometry(Import& import);

// ---- gltf/materials.cpp ----

struct Materials {
  std::vector<uint32_t> index;        // scene material of each glTF material
  uint32_t default_index = kNoLight;  // the glTF default material, made when first used
  // The glTF default material (spec 3.9.6) in the scene, made on first use.
  uint32_t default_material(Import& import);
};

// gltf_pbr parameters for glTF material `m` (spec 3.9, appendix B; the KHR_materials_* extensions), textures included.
json material_params(const json& doc, const json& m, std::vector<std::string>* warnings);

// glTF material `material` with KHR_materials_pbrSpecularGlossiness as a metallic-roughness material (the
// extension's conversion example); a specular-glossiness texture is baked into a metallic-roughness image added to
// `images` and to doc's images and textures. A warning says it is approximated.
json spec_gloss_to_metal_rough(json& doc, const json& material,
                               std::map<std::string, std::shared_ptr<const ImagePixels>>& images,
                               std::vector<std::string>* warnings);

// Sets each primitive's material to its KHR_materials_variants mapping for options.variant, if one is chosen.
void apply_variant(Import& import);

// Makes the glTF materials (replaced by the job's of the same name) in the scene, textures from `images`.
Materials make_materials(Import& import, std::map<std::string, std::shared_ptr<const ImagePixels>> images);

// ---- gltf/meshes.cpp ----

// Reads accessors with every offset checked against the bytes that exist; SceneError at `pointer` otherwise.
class AccessorReader {
 public:
  // Accessors without a buffer view are counted against `budget` before they are made.
  AccessorReader(const tinygltf::Model& model, const std::string& pointer, DecodeBudget& budget)
      : model_(model), pointer_(pointer), budget_(budget) {}
  // Accessor `index` as floats, `components` per element (normalised integers mapped to [0,1] / [-1,1]).
  std::vector<float> floats(int index, int components) const;
  // Accessor `index` as triangle indices, each below `vertex_count`.
  std::vector<uint32_t> indices(int index, size_t vertex_count) const;
  size_t count(int index) const;

 private:
  [[noreturn]] void fail(int index, const std::string& what) const;
  const tinygltf::Accessor& accessor(int index) const;
  struct Layout;
  Layout layout(const tinygltf::Accessor& acc, int index) const;
  template <typename Fn>
  void read(const tinygltf::Accessor& acc, int index, const Layout& at, Fn&& fn) const;
  void view(int view_index, int accessor_index, const unsigned char** base, size_t* length, size_t* stride) const;

  const tinygltf::Model& model_;
  std::string pointer_;
  DecodeBudget& budget_;
};

// The triangles of glTF mesh `mesh_index` under transform `world` (identity for instanced prototypes), one Mesh per
// triangle primitive, counted into import.triangles. With `joints` (a skin's joint matrices: joint world transform
// times inverse bind matrix), each vertex is moved by the blend of its JOINTS_0 matrices by WEIGHTS_0 (glTF 2.0,
// 3.7.3 "Skins"), and `world` is not used. Morph targets are applied at `weights` (a pose's, animated), or at the
// mesh's default weights when it is null or empty.
std::vector<Mesh> build_meshes(Import& import, const AccessorReader& reader, Materials& materials, int mesh_index,
                               const TransformD& world, const std::vector<TransformD>* joints = nullptr,
                               const std::vector<double>* weights = nullptr);

// ---- gltf/animation.cpp ----

// A node's local transform as the asset states it (glTF 2.0, 3.5.2 "Transformations"): a matrix, or a translation, a
// rotation (a unit quaternion x, y, z, w) and a scale, the properties animations target.
struct NodeTransform {
  std::vector<double> matrix;  // 16 values, column-major; empty: translation * rotation * scale
  double translation[3] = {0, 0, 0};
  double rotation[4] = {0, 0, 0, 1};
  double scale[3] = {1, 1, 1};
  static NodeTransform of(const tinygltf::Node& node);
  TransformD local() const;
};

// Every node's local transform and morph weights at one time: what the scene graph is walked with. weights[n] empty
// means the node's mesh's default weights.
struct Pose {
  std::vector<NodeTransform> nodes;
  std::vector<std::vector<double>> weights;
};

// The nodes as the asset states them (no animation applied): the pose of a still without scene.time.
Pose static_pose(const tinygltf::Model& model);

// One animation sampler's keyframes (glTF 2.0, 3.11 "Animations"), evaluated at any time by the interpolation of the
// specification's Appendix C.
struct AnimationSampler {
  enum class Interpolation { kLinear, kStep, kCubicSpline };
  Interpolation interpolation = Interpolation::kLinear;
  std::vector<float> times;   // seconds, strictly increasing
  std::vector<float> values;  // `width` per keyframe; CUBICSPLINE: in-tangent, value, out-tangent per keyframe
  int width = 1;
  bool rotation = false;  // unit quaternions: spherical interpolation, results normalised
  // The value at `t` seconds (`width` numbers into `out`); before the first keyframe the first value, after the last
  // the last.
  void evaluate(double t, double* out) const;
};

// One channel: a sampler driving one property of one node.
struct AnimationChannel {
  enum class Path { kTranslation, kRotation, kScale, kWeights };
  int node = -1;
  Path path = Path::kTranslation;
  int sampler = -1;  // in Animation::samplers
};

// An animation's channels with their samplers' keyframes read (bounded by the accessor reader's limits): posing the
// scene at any time reads nothing more, so that several times (frames, a shutter's interval) can be posed from it.
struct Animation {
  std::string name;
  std::vector<AnimationSampler> samplers;
  std::vector<AnimationChannel> channels;
  // Sets the properties the channels target in `pose` to their values at `t` seconds; the rest stay as they are.
  void pose_at(double t, Pose& pose) const;
};

// The animation the options choose (options.animate; by options.animation_name or options.animation_index, else the
// asset's first), read; nullopt for the static pose. SceneError at options.animation_pointer for a name or index the
// asset does not have; warnings for the animations not applied.
std::optional<Animation> chosen_animation(Import& import);

// Animation `index` of the asset, its channels' samplers read through `reader`. Throws SceneError for keyframes that
// do not match the specification (times not increasing, an output count that does not fit the input's).
Animation read_animation(Import& import, const AccessorReader& reader, int index);

// ---- gltf/nodes.cpp ----

// The root nodes of the default scene (or, without scenes, every node that is nobody's child), after checking that
// walking them makes at most options.max_instances node instances.
std::vector<int> scene_roots(const Import& import);

// Walks the node hierarchy from `roots` in `pose`: meshes placed (instanced when several nodes share one), skins posed
// by their joints' transforms in it, EXT_mesh_gpu_instancing expanded, cameras and KHR_lights_punctual lights into
// import.result.
void place_nodes(Import& import, Materials& materials, const std::vector<int>& roots, const Pose& pose);

// Motion blur: the nodes posed by `animation` at each of options.shutter_times (after `time`), walked as place_nodes
// walks them, their meshes and cameras kept as the poses of those place_nodes placed at the frame's time: the scene's
// meshes from `first_mesh` and the result's cameras from `first_camera` (the same walk makes them in the same order).
// A mesh or camera that moves over the steps gets them (Mesh::motion_positions and motion_normals,
// GltfCamera::motion); emissive meshes keep the frame's pose.
void place_motion_steps(Import& import, Materials& materials, const std::vector<int>& roots, const Animation& animation,
                        size_t first_mesh, size_t first_camera);

}  // namespace tessera::gltf
