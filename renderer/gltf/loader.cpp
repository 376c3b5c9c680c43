// import_gltf: the asset read (gltf/files.cpp), its materials made (gltf/materials.cpp), its nodes posed
// (gltf/animation.cpp), its scene graph walked (gltf/nodes.cpp) and its meshes built on the way (gltf/meshes.cpp); the
// parts share renderer/gltf/internal.h.
#include "renderer/gltf/loader.h"

#include "renderer/gltf/internal.h"

namespace tessera {

GltfImport import_gltf(const std::filesystem::path& path, const std::string& pointer, Scene& scene,
                       const GltfImportOptions& options) {
  GltfImport result;
  gltf::Import import(path, pointer, scene, options, result);
  gltf::read_asset(import);
  // The nodes to render, and how many instances of them the walk will make: bounded before anything is made.
  const std::vector<int> roots = gltf::scene_roots(import);
  import.check_stop();
  gltf::decode_compressed_geometry(import);
  gltf::apply_variant(import);
  // The animation to pose the nodes by, if one is chosen: its keyframes read (and a bad choice refused) before the
  // images are decoded.
  const std::optional<gltf::Animation> animation = gltf::chosen_animation(import);
  // Images, decoded once, shared by every texture that uses them (as "#image<i>").
  gltf::Materials materials = gltf::make_materials(import, gltf::decode_images(import));
  import.triangles = scene.triangle_count();
  // The nodes as stated, or posed by the chosen animation at the chosen time.
  gltf::Pose pose = gltf::static_pose(import.model);
  if (animation) animation->pose_at(options.time, pose);
  const size_t first_mesh = scene.meshes.size(), first_camera = result.cameras.size();
  gltf::place_nodes(import, materials, roots, pose);
  if (animation && !options.shutter_times.empty())
    gltf::place_motion_steps(import, materials, roots, *animation, first_mesh, first_camera);
  if (!import.tinygltf_warnings.empty()) result.warnings.push_back(import.tinygltf_warnings);
  // Each warning once (a mesh drawn by many nodes says it once), and not too many.
  tidy_warnings(&result.warnings);
  return result;
}

}  // namespace tessera
