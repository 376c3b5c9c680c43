// The glTF scene graph: which nodes a scene holds, their transforms in a pose (glTF 2.0, 3.5; as stated, or animated
// by gltf/animation.cpp), meshes placed and instanced (shared meshes, EXT_mesh_gpu_instancing), skins posed by their
// joints, cameras and KHR_lights_punctual lights.
#include <cmath>
#include <functional>

#include "renderer/gltf/internal.h"

namespace tessera::gltf {

namespace {

// The node instances a walk from `roots` makes: a node counts once per path that reaches it. The specification wants
// the hierarchy to be disjoint trees (glTF 2.0, section 3.5.3), where this is the number of nodes; a file whose nodes
// share children is still read (as instancing), and its count grows with the paths: a chain of n nodes each listing
// the next four times makes 4^n. Counted per node once (memoised), in time linear in the nodes and child lists;
// returns at most limit + 1. Throws SceneError at `pointer` for a cycle, a node that does not exist or a hierarchy
// deeper than 256 levels.
uint64_t count_node_instances(const tinygltf::Model& model, const std::vector<int>& roots, uint64_t limit,
                              const std::string& pointer) {
  const int nodes = static_cast<int>(model.nodes.size());
  std::vector<uint64_t> subtree(model.nodes.size(), 0);  // instances a node makes with its descendants; 0: not counted
  std::vector<bool> on_path(model.nodes.size(), false);
  std::function<uint64_t(int, int)> count = [&](int n, int depth) -> uint64_t {
    if (n < 0 || n >= nodes) throw SceneError(pointer, "node " + std::to_string(n) + " does not exist");
    if (on_path[n]) throw SceneError(pointer, "node " + std::to_string(n) + " is its own ancestor (a cycle)");
    if (depth > 256) throw SceneError(pointer, "the node hierarchy is deeper than 256 levels");
    if (subtree[n] == 0) {
      on_path[n] = true;
      uint64_t total = 1;
      for (int child : model.nodes[n].children) total = std::min(total + count(child, depth + 1), limit + 1);
      on_path[n] = false;
      subtree[n] = total;
    }
    return subtree[n];
  };
  uint64_t total = 0;
  for (int root : roots) total = std::min(total + count(root, 0), limit + 1);
  return total;
}

}  // namespace

std::vector<int> scene_roots(const Import& import) {
  const tinygltf::Model& model = import.model;
  const GltfImportOptions& options = import.options;
  const std::string& pointer = import.pointer;
  std::vector<int> roots;
  // glTF 2.0, 5.17 (glTF.scene): the index of the default scene, which must exist.
  if (model.defaultScene < -1 || model.defaultScene >= static_cast<int>(model.scenes.size()))
    throw SceneError(pointer, "the asset's scene " + std::to_string(model.defaultScene) + " does not exist (it has " +
                                  std::to_string(model.scenes.size()) + " scenes)");
  int scene_index = model.defaultScene >= 0 ? model.defaultScene : (model.scenes.empty() ? -1 : 0);
  if (scene_index >= 0 && scene_index < static_cast<int>(model.scenes.size())) {
    roots = model.scenes[scene_index].nodes;
  } else {
    // No scenes: render every node that is nobody's child.
    std::vector<bool> is_child(model.nodes.size(), false);
    for (const auto& n : model.nodes)
      for (int c : n.children)
        if (c >= 0 && c < static_cast<int>(is_child.size())) is_child[c] = true;
    for (size_t i = 0; i < model.nodes.size(); ++i)
      if (!is_child[i]) roots.push_back(static_cast<int>(i));
  }
  if (count_node_instances(model, roots, options.max_instances, pointer) > options.max_instances)
    throw SceneError(pointer, "the node hierarchy makes more than " + std::to_string(options.max_instances) +
                                  " node instances, the limit (a node counts once per path to it from the scene: "
                                  "children that nodes share multiply)");
  return roots;
}

void place_nodes(Import& import, Materials& materials, const std::vector<int>& roots, const Pose& pose) {
  const tinygltf::Model& model = import.model;
  const GltfImportOptions& options = import.options;
  const std::string& pointer = import.pointer;
  Scene& scene = import.scene;
  GltfImport& result = import.result;
  const auto check_stop = [&import] { import.check_stop(); };
  const AccessorReader reader(model, pointer, import.decoded);
  std::set<int> instanced;
  std::map<int, uint32_t> group_of_mesh;
  std::map<int, size_t> camera_instances;

  // EXT_mesh_gpu_instancing: the node's mesh drawn once per instance, at the node's transform times the instance's
  // TRANSLATION * ROTATION * SCALE (each attribute optional; the extension's specification). Empty without it.
  uint64_t gpu_instances_made = 0;
  auto gpu_instance_count = [&](const tinygltf::Node& node) -> size_t {
    const json ext = parse_extensions(node.extensions_json_string);
    if (!ext.contains("EXT_mesh_gpu_instancing")) return 0;
    const json attrs = ext["EXT_mesh_gpu_instancing"].value("attributes", json::object());
    for (const char* key : {"TRANSLATION", "ROTATION", "SCALE"})
      if (attrs.contains(key) && attrs[key].is_number_integer()) return reader.count(attrs[key].get<int>());
    return 0;
  };
  auto gpu_instances = [&](const tinygltf::Node& node, int node_index) -> std::vector<TransformD> {
    const size_t n = gpu_instance_count(node);
    if (n == 0) return {};
    gpu_instances_made += n;
    if (gpu_instances_made > options.max_instances)
      throw SceneError(pointer, "EXT_mesh_gpu_instancing makes more than " + std::to_string(options.max_instances) +
                                    " instances, the limit");
    const json attrs = parse_extensions(node.extensions_json_string)["EXT_mesh_gpu_instancing"]["attributes"];
    auto read = [&](const char* key, int components) {
      std::vector<float> v;
      if (!attrs.contains(key) || !attrs[key].is_number_integer()) return v;
      if (reader.count(attrs[key].get<int>()) != n)
        throw SceneError(pointer, "node " + std::to_string(node_index) + ": EXT_mesh_gpu_instancing's " + key +
                                      " has another count than its other attributes");
      v = reader.floats(attrs[key].get<int>(), components);
      return v;
    };
    const std::vector<float> t = read("TRANSLATION", 3), r = read("ROTATION", 4), sc = read("SCALE", 3);
    std::vector<TransformD> out(n);
    for (size_t i = 0; i < n; ++i) {
      check_stop();
      tinygltf::Node trs;
      if (!t.empty()) trs.translation = {t[3 * i], t[3 * i + 1], t[3 * i + 2]};
      if (!r.empty()) trs.rotation = {r[4 * i], r[4 * i + 1], r[4 * i + 2], r[4 * i + 3]};
      if (!sc.empty()) trs.scale = {sc[3 * i], sc[3 * i + 1], sc[3 * i + 2]};
      out[i] = NodeTransform::of(trs).local();
    }
    return out;
  };

  std::vector<TransformD> node_world;  // filled before the walk
  std::function<void(int, const TransformD&, int)> visit = [&](int node_index, const TransformD& parent, int depth) {
    if (node_index < 0 || node_index >= static_cast<int>(model.nodes.size()))
      throw SceneError(pointer, "node " + std::to_string(node_index) + " does not exist");
    if (depth > 256) throw SceneError(pointer, "the node hierarchy is deeper than 256 levels (a cycle?)");
    check_stop();
    const tinygltf::Node& node = model.nodes[node_index];
    // The node's morph weights in the pose (animated), else its mesh's default weights.
    const std::vector<double>& weights = pose.weights[node_index];
    if (!node.weights.empty() && weights.empty() && node.mesh >= 0 &&
        node.mesh < static_cast<int>(model.meshes.size()) && node.weights != model.meshes[node.mesh].weights)
      result.warnings.push_back("node " + std::to_string(node_index) +
                                ": its own morph weights are not applied (the mesh's default weights are)");
    const TransformD world = parent * pose.nodes[node_index].local();
    // The name of what the node draws, for Cryptomatte's object mattes: the node's, else its mesh's (as Blender's
    // importer names an unnamed node), else its number.
    std::string object_name = node.name;
    if (object_name.empty() && node.mesh >= 0 && node.mesh < static_cast<int>(model.meshes.size()))
      object_name = model.meshes[node.mesh].name;
    if (object_name.empty()) object_name = "node " + std::to_string(node_index);

    if (node.mesh >= 0) {
      if (node.mesh >= static_cast<int>(model.meshes.size()))
        throw SceneError(pointer, "node " + std::to_string(node_index) + " names mesh " + std::to_string(node.mesh) +
                                      ", which does not exist");
      // The mesh at transform `at`: an instance of its one object-space copy, or triangles of its own.
      auto place = [&](const TransformD& at) {
        if (instanced.count(node.mesh) && weights.empty()) {
          // Shared by several nodes: one object-space copy, one Embree instance per node.
          auto [it, fresh] = group_of_mesh.try_emplace(node.mesh, static_cast<uint32_t>(scene.groups.size()));
          if (fresh) {
            MeshGroup group;
            for (Mesh& m : build_meshes(import, reader, materials, node.mesh, TransformD())) {
              m.prototype = true;
              group.meshes.push_back(static_cast<uint32_t>(scene.meshes.size()));
              scene.meshes.push_back(std::move(m));
            }
            scene.groups.push_back(std::move(group));
          }
          Instance inst;
          inst.group = it->second;
          inst.to_world = at.cast<float>();
          inst.normal_to_world = at.normal_transform().cast<float>();
          inst.mirrored = at.determinant() < 0;
          inst.name = object_name;
          for (uint32_t m : scene.groups[inst.group].meshes) {
            if (!fresh) import.triangles += scene.meshes[m].triangle_count();  // build_meshes counted the first
            for (const Vec3& p : scene.meshes[m].positions) result.bounds.extend(inst.to_world.point(p));
          }
          import.check_triangles();
          scene.instances.push_back(inst);
        } else {
          for (Mesh& m : build_meshes(import, reader, materials, node.mesh, at, nullptr, &weights)) {
            for (const Vec3& p : m.positions) result.bounds.extend(p);
            m.name = object_name;
            scene.meshes.push_back(std::move(m));
          }
        }
      };
      const std::vector<TransformD> copies = gpu_instances(node, node_index);
      if (node.skin >= 0) {
        // Posed by its joints' node transforms in the pose (animated or as stated); the node's own transform is
        // not used (glTF 2.0, 3.7.3).
        if (node.skin >= static_cast<int>(model.skins.size()))
          throw SceneError(pointer, "node " + std::to_string(node_index) + " names a skin that does not exist");
        const tinygltf::Skin& skin = model.skins[node.skin];
        std::vector<float> ibm;
        if (skin.inverseBindMatrices >= 0) ibm = reader.floats(skin.inverseBindMatrices, 16);
        if (!ibm.empty() && ibm.size() != skin.joints.size() * 16)
          throw SceneError(pointer,
                           "skin " + std::to_string(node.skin) + ": inverseBindMatrices has another count than joints");
        std::vector<TransformD> joints(skin.joints.size());
        for (size_t j = 0; j < joints.size(); ++j) {
          const int jn = skin.joints[j];
          if (jn < 0 || jn >= static_cast<int>(node_world.size()))
            throw SceneError(pointer, "skin " + std::to_string(node.skin) + " names a joint that does not exist");
          TransformD inverse_bind;
          if (!ibm.empty()) {
            double column_major[16];
            std::copy(ibm.begin() + 16 * j, ibm.begin() + 16 * (j + 1), column_major);
            inverse_bind = TransformD::from_column_major(column_major);
          }
          joints[j] = node_world[jn] * inverse_bind;
        }
        for (Mesh& m : build_meshes(import, reader, materials, node.mesh, TransformD(), &joints, &weights)) {
          for (const Vec3& p : m.positions) result.bounds.extend(p);
          m.name = object_name;
          scene.meshes.push_back(std::move(m));
        }
      } else if (copies.empty()) {
        place(world);
      }
      for (const TransformD& local : copies) place(world * local);
    }

    if (node.camera >= 0 && node.camera < static_cast<int>(model.cameras.size()) &&
        !camera_instances.count(node.camera)) {
      const tinygltf::Camera& cam = model.cameras[node.camera];
      GltfCamera gc;
      gc.name = cam.name;
      // A glTF camera looks down its local -Z with +Y up (spec 3.10).
      gc.desc.from = world.point(Vec3(0, 0, 0));
      gc.desc.to = gc.desc.from + normalize(world.vector(Vec3(0, 0, -1)));
      gc.desc.up = normalize(world.vector(Vec3(0, 1, 0)));
      if (cam.type == "orthographic") {
        gc.desc.projection = CameraDesc::Projection::kOrthographic;
        gc.desc.ortho_height = static_cast<float>(2 * cam.orthographic.ymag);
        if (cam.orthographic.ymag > 0)
          gc.aspect_ratio = static_cast<float>(cam.orthographic.xmag / cam.orthographic.ymag);
      } else {
        gc.desc.fov_deg = static_cast<float>(cam.perspective.yfov * 180 / M_PI);
        gc.aspect_ratio = static_cast<float>(cam.perspective.aspectRatio);
      }
      camera_instances[node.camera] = result.cameras.size();
      result.cameras.push_back(gc);
    }

    json ext = parse_extensions(node.extensions_json_string);
    if (ext.contains("KHR_lights_punctual") && ext["KHR_lights_punctual"].contains("light")) {
      int li =
          ext["KHR_lights_punctual"]["light"].is_number_integer() ? ext["KHR_lights_punctual"]["light"].get<int>() : -1;
      if (li < 0 || li >= static_cast<int>(model.lights.size()))
        throw SceneError(pointer, "node " + std::to_string(node_index) + " names a light that does not exist");
      const tinygltf::Light& l = model.lights[li];
      PunctualLight pl;
      Rgb color(1);
      if (l.color.size() == 3)
        color = Rgb(static_cast<float>(l.color[0]), static_cast<float>(l.color[1]), static_cast<float>(l.color[2]));
      // KHR_lights_punctual units: point and spot in candela, directional in lux; used as W/sr and W/m^2 (the
      // luminous efficacy is a constant factor that exposure absorbs).
      pl.intensity = color * static_cast<float>(l.intensity);
      pl.position = world.point(Vec3(0, 0, 0));
      pl.direction = normalize(world.vector(Vec3(0, 0, -1)));
      if (l.type == "directional") {
        pl.kind = PunctualLight::Kind::kDirectional;
      } else if (l.type == "spot") {
        pl.kind = PunctualLight::Kind::kSpot;
        pl.cos_inner = static_cast<float>(std::cos(l.spot.innerConeAngle));
        pl.cos_outer = static_cast<float>(std::cos(l.spot.outerConeAngle));
      } else {
        pl.kind = PunctualLight::Kind::kPoint;
      }
      result.lights.push_back(pl);
    }

    for (int child : node.children) visit(child, world, depth + 1);
  };

  // Meshes that several nodes reference are instanced, unless they emit (lights are sampled in world space).
  std::map<int, int> references;
  std::function<void(int, int)> census = [&](int n, int depth) {
    if (n < 0 || n >= static_cast<int>(model.nodes.size()) || depth > 256) return;
    check_stop();
    if (model.nodes[n].mesh >= 0)
      references[model.nodes[n].mesh] += static_cast<int>(std::max<size_t>(1, gpu_instance_count(model.nodes[n])));
    for (int c : model.nodes[n].children) census(c, depth + 1);
  };
  for (int r : roots) census(r, 0);
  for (auto [mesh_index, count] : references) {
    if (count < 2 || mesh_index >= static_cast<int>(model.meshes.size())) continue;
    bool emits = false;
    for (const tinygltf::Primitive& prim : model.meshes[mesh_index].primitives)
      if (prim.material >= 0 && prim.material < static_cast<int>(materials.index.size()))
        emits = emits || scene.materials[materials.index[prim.material]]->emissive();
    // Under a shutter every mesh is placed in world space, so that each copy gets its own time steps.
    if (!emits && options.shutter_times.empty()) instanced.insert(mesh_index);
  }
  // Every node's world transform (of its first path from the scene), for the joints of skins, which need not be
  // ancestors of the meshes they pose.
  node_world.assign(model.nodes.size(), TransformD());
  {
    std::vector<bool> placed(model.nodes.size(), false);
    std::function<void(int, const TransformD&, int)> walk = [&](int n, const TransformD& parent, int depth) {
      if (n < 0 || n >= static_cast<int>(model.nodes.size()) || depth > 256 || placed[n]) return;
      placed[n] = true;
      node_world[n] = parent * pose.nodes[n].local();
      for (int c : model.nodes[n].children) walk(c, node_world[n], depth + 1);
    };
    for (int r : roots) walk(r, TransformD(), 0);
  }
  for (int r : roots) visit(r, TransformD(), 0);
}

}  // namespace tessera::gltf

namespace tessera::gltf {

namespace {

// Whether every step holds the same values (nothing moves over the shutter).
bool still(const std::vector<std::vector<Vec3>>& steps) {
  for (const std::vector<Vec3>& step : steps)
    if (step != steps.front()) return false;
  return true;
}

bool same_pose(const CameraDesc& a, const CameraDesc& b) {
  return a.from == b.from && a.to == b.to && a.up == b.up && a.fov_deg == b.fov_deg && a.ortho_height == b.ortho_height;
}

}  // namespace

void place_motion_steps(Import& import, Materials& materials, const std::vector<int>& roots, const Animation& animation,
                        size_t first_mesh, size_t first_camera) {
  Scene& scene = import.scene;
  GltfImport& result = import.result;
  const size_t meshes = scene.meshes.size(), cameras = result.cameras.size();
  const std::vector<double>& offsets = import.options.shutter_times;
  std::vector<std::vector<std::vector<Vec3>>> positions(meshes - first_mesh), normals(meshes - first_mesh);
  std::vector<std::vector<CameraDesc>> camera_steps(cameras - first_camera);
  // What the frame's walk counted and reported stands: each step's walk places the same meshes again, briefly. The
  // asset's bounds stay the frame's (a camera made to frame the asset frames it as without a shutter).
  const size_t triangles = import.triangles, vertices = import.vertices, lights = result.lights.size(),
               warnings = result.warnings.size();
  const Bounds bounds = result.bounds;
  for (const double offset : offsets) {
    import.check_stop();
    Pose pose = static_pose(import.model);
    animation.pose_at(import.options.time + offset, pose);
    place_nodes(import, materials, roots, pose);
    if (scene.meshes.size() - meshes != meshes - first_mesh ||
        result.cameras.size() - cameras != cameras - first_camera)
      import.fail("the asset's nodes placed different meshes at the shutter's times than at the frame's");
    for (size_t m = 0; m < positions.size(); ++m) {
      Mesh& step = scene.meshes[meshes + m];
      if (step.positions.size() != scene.meshes[first_mesh + m].positions.size())
        import.fail("a mesh has different vertices at the shutter's times than at the frame's");
      positions[m].push_back(std::move(step.positions));
      normals[m].push_back(std::move(step.normals));
    }
    for (size_t c = 0; c < camera_steps.size(); ++c) camera_steps[c].push_back(result.cameras[cameras + c].desc);
    scene.meshes.resize(meshes);
    result.cameras.resize(cameras);
    result.lights.resize(lights);
    result.warnings.resize(warnings);
    import.triangles = triangles;
    import.vertices = vertices;
    result.bounds = bounds;
  }
  for (size_t m = 0; m < positions.size(); ++m) {
    Mesh& mesh = scene.meshes[first_mesh + m];
    if (still(positions[m]) || scene.materials[mesh.material]->emissive()) continue;
    mesh.motion_positions = std::move(positions[m]);
    if (!mesh.normals.empty()) mesh.motion_normals = std::move(normals[m]);
  }
  for (size_t c = 0; c < camera_steps.size(); ++c) {
    const std::vector<CameraDesc>& steps = camera_steps[c];
    if (std::all_of(steps.begin(), steps.end(), [&](const CameraDesc& d) { return same_pose(d, steps.front()); }))
      continue;
    result.cameras[first_camera + c].motion = steps;
  }
}

}  // namespace tessera::gltf
