#include "renderer/scene_loader.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "proto/asset_path.h"
#include "proto/did_you_mean.h"
#include "renderer/gltf/loader.h"
#include "renderer/grid_medium.h"
#include "renderer/json_fields.h"
#include "renderer/scene_error.h"
#include "renderer/thread_pool.h"

namespace tessera {

using nlohmann::json;

namespace {

using fields::at;
using fields::finite_number;
using fields::number_key;

const json& require(const json& obj, const std::string& key, const std::string& pointer) {
  auto it = obj.find(key);
  if (it == obj.end()) throw SceneError(at(pointer, key), "\"" + key + "\" is required");
  return *it;
}

Vec3 vec3(const json& v, const std::string& pointer) {
  if (!v.is_array() || v.size() != 3) throw SceneError(pointer, "must be an array of 3 numbers");
  return Vec3(static_cast<float>(finite_number(v[0], at(pointer, 0))),
              static_cast<float>(finite_number(v[1], at(pointer, 1))),
              static_cast<float>(finite_number(v[2], at(pointer, 2))));
}

Vec3 vec3_key(const json& obj, const std::string& key, const std::string& pointer) {
  return vec3(require(obj, key, pointer), at(pointer, key));
}

template <typename T, int N>
std::vector<T> flat_array(const json& obj, const std::string& key, const std::string& pointer, bool required) {
  std::vector<T> out;
  auto it = obj.find(key);
  if (it == obj.end()) {
    if (required) throw SceneError(at(pointer, key), "\"" + key + "\" is required");
    return out;
  }
  const std::string p = at(pointer, key);
  if (!it->is_array()) throw SceneError(p, "must be a flat array of numbers");
  if (it->size() % N != 0) throw SceneError(p, "must hold a multiple of " + std::to_string(N) + " numbers");
  out.resize(it->size() / N);
  for (size_t i = 0; i < it->size(); ++i) {
    float v = static_cast<float>(finite_number((*it)[i], at(p, i)));
    reinterpret_cast<float*>(out.data())[i] = v;
  }
  return out;
}

uint32_t material_index(const json& obj, const std::string& pointer, const std::map<std::string, uint32_t>& names) {
  const json& m = require(obj, "material", pointer);
  if (!m.is_string()) throw SceneError(at(pointer, "material"), "must be the name of a material");
  auto it = names.find(m.get<std::string>());
  if (it == names.end()) {
    std::vector<std::string> known;
    for (const auto& [name, index] : names) known.push_back(name);
    throw SceneError(at(pointer, "material"), "unknown material \"" + m.get<std::string>() + "\"" +
                                                  proto::did_you_mean(m.get<std::string>(), known));
  }
  return it->second;
}

void load_mesh(const json& obj, const std::string& pointer, uint32_t material, Scene& scene, size_t* triangles,
               size_t max_triangles) {
  Mesh mesh;
  mesh.material = material;
  mesh.positions = flat_array<Vec3, 3>(obj, "positions", pointer, true);
  const json& idx = require(obj, "indices", pointer);
  const std::string ip = at(pointer, "indices");
  if (!idx.is_array() || idx.size() % 3 != 0 || idx.empty())
    throw SceneError(ip, "must be a non-empty flat array of vertex indices, 3 per triangle");
  *triangles += idx.size() / 3;
  if (*triangles > max_triangles)
    throw SceneError(ip, "the scene exceeds the limit of " + std::to_string(max_triangles) + " triangles");
  mesh.indices.resize(idx.size());
  for (size_t i = 0; i < idx.size(); ++i) {
    const json& v = idx[i];
    if (!v.is_number_integer() || v.get<int64_t>() < 0 ||
        v.get<int64_t>() >= static_cast<int64_t>(mesh.positions.size()))
      throw SceneError(at(ip, i), "must be a vertex index below " + std::to_string(mesh.positions.size()));
    mesh.indices[i] = static_cast<uint32_t>(v.get<int64_t>());
  }
  mesh.normals = flat_array<Vec3, 3>(obj, "normals", pointer, false);
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size())
    throw SceneError(at(pointer, "normals"), "must have one normal per position");
  mesh.uvs = flat_array<Vec2, 2>(obj, "uvs", pointer, false);
  if (!mesh.uvs.empty() && mesh.uvs.size() != mesh.positions.size())
    throw SceneError(at(pointer, "uvs"), "must have one uv pair per position");
  for (Vec2& uv : mesh.uvs) uv.y = 1 - uv.y;  // scene uvs have v up; textures are addressed top-down
  scene.meshes.push_back(std::move(mesh));
}

void load_rectangle(const json& obj, const std::string& pointer, uint32_t material, Scene& scene) {
  // A parallelogram: corner + edge1 + edge2; its front faces along edge1 x edge2.
  Vec3 c = vec3_key(obj, "corner", pointer);
  Vec3 e1 = vec3_key(obj, "edge1", pointer);
  Vec3 e2 = vec3_key(obj, "edge2", pointer);
  if (!(length(cross(e1, e2)) > 0)) throw SceneError(at(pointer, "edge2"), "edge1 and edge2 must not be parallel");
  Mesh mesh;
  mesh.material = material;
  mesh.positions = {c, c + e1, c + e1 + e2, c + e2};
  mesh.indices = {0, 1, 2, 0, 2, 3};
  mesh.uvs = {Vec2(0, 1), Vec2(1, 1), Vec2(1, 0), Vec2(0, 0)};
  scene.meshes.push_back(std::move(mesh));
}

CameraDesc load_camera(const json& cam, const std::string& pointer) {
  if (!cam.is_object()) throw SceneError(pointer, "must be an object");
  CameraDesc desc;
  std::string type = cam.value("type", std::string("perspective"));
  if (type == "perspective")
    desc.projection = CameraDesc::Projection::kPerspective;
  else if (type == "orthographic")
    desc.projection = CameraDesc::Projection::kOrthographic;
  else
    throw SceneError(at(pointer, "type"), "must be \"perspective\" or \"orthographic\"");
  desc.from = vec3_key(cam, "from", pointer);
  desc.to = vec3_key(cam, "to", pointer);
  if (cam.contains("up")) desc.up = vec3(cam["up"], at(pointer, "up"));
  if (!(length(desc.to - desc.from) > 0)) throw SceneError(at(pointer, "to"), "must differ from \"from\"");
  if (!(length(desc.up) > 0)) throw SceneError(at(pointer, "up"), "must not be the zero vector");
  if (length(cross(normalize(desc.to - desc.from), normalize(desc.up))) < 1e-6f)
    throw SceneError(at(pointer, "up"), "must not be parallel to the viewing direction");
  desc.fov_deg = number_key(cam, "fov_deg", pointer, 40, 0, 179, true);
  desc.ortho_height = number_key(cam, "height", pointer, 2, 0, 1e9, true);
  desc.aperture_radius = number_key(cam, "aperture_radius", pointer, 0, 0, 1e6);
  desc.focus_distance = number_key(cam, "focus_distance", pointer, 0, 0, 1e9);
  return desc;
}

std::filesystem::path resolve(const SceneLoadOptions& options, const json& ref, const std::string& pointer) {
  if (!ref.is_string() || ref.get<std::string>().empty()) throw SceneError(pointer, "must name an asset");
  const std::string name = ref.get<std::string>();
  if (options.resolve_asset) return options.resolve_asset(name, pointer);
  if (options.asset_root.empty()) throw SceneError(pointer, "this document cannot reference files");
  // A file of the scene's folder or its subfolders, never outside it (proto/asset_path.h).
  const proto::AssetPath file = proto::asset_path(name);
  if (!file.problem.empty()) throw SceneError(pointer, "\"" + name.substr(0, 200) + "\" is refused: " + file.problem);
  bool outside = false;
  auto full = proto::confined_file(options.asset_root, file.path, &outside);
  if (!full && outside) throw SceneError(pointer, "\"" + name + "\" resolves outside the scene's folder");
  if (!full) throw SceneError(pointer, "no such file: " + name);
  return *full;
}

// The keys of a medium's object: a homogeneous medium's, and those a medium from a grid adds.
const std::vector<std::string> kMediumKeys = {"sigma_a", "sigma_s", "g"};
const std::vector<std::string> kGridMediumKeys = {"sigma_a",       "sigma_s",   "g",     "grid",    "grid_name",
                                                  "density_scale", "translate", "scale", "majorant"};

// Refuses a key a medium (from a grid when `grid`) does not have, saying when it is a grid's key without "grid".
void check_medium_keys(const json& m, const std::string& pointer, bool grid) {
  const auto& known = grid ? kGridMediumKeys : kMediumKeys;
  for (const auto& [key, value] : m.items()) {
    if (std::find(known.begin(), known.end(), key) != known.end()) continue;
    const bool grid_key = std::find(kGridMediumKeys.begin(), kGridMediumKeys.end(), key) != kGridMediumKeys.end();
    throw SceneError(at(pointer, key),
                     "unknown medium parameter \"" + key.substr(0, 64) + "\"" + proto::did_you_mean(key, known) +
                         (grid_key ? " (it is a parameter of a medium from a grid, with \"grid\")" : ""));
  }
}

// The medium from a grid of `m` (its coefficients read already into `desc`): the grid's file and name, where it lies,
// its density scale and majorant.
std::shared_ptr<const Medium> grid_medium_of(const json& m, const std::string& pointer, const SceneLoadOptions& options,
                                             GridMediumDesc desc) {
  desc.density_scale = number_key(m, "density_scale", pointer, 1, 0, 1e9);
  desc.scale = number_key(m, "scale", pointer, 1, 0, 1e9, true);
  if (auto it = m.find("translate"); it != m.end()) desc.translate = vec3(*it, at(pointer, "translate"));
  if (auto it = m.find("grid_name"); it != m.end()) {
    if (!it->is_string() || it->get_ref<const std::string&>().empty() || it->get_ref<const std::string&>().size() > 256)
      throw SceneError(at(pointer, "grid_name"), "must be a grid's name of 1 to 256 characters");
    desc.grid_name = it->get<std::string>();
  }
  if (auto it = m.find("majorant"); it != m.end()) {
    if (*it != "grid" && *it != "global") throw SceneError(at(pointer, "majorant"), "must be \"grid\" or \"global\"");
    desc.majorant_grid = *it == "grid";
  }
  desc.max_voxels = options.max_grid_voxels;
  desc.file = resolve(options, m["grid"], at(pointer, "grid"));
  try {
    return load_grid_medium(desc);
  } catch (const GridError& e) {
    throw SceneError(at(pointer, e.field), e.what());
  }
}

// A medium from {"sigma_a": [r, g, b], "sigma_s": [r, g, b], "g": 0} (coefficients per scene unit, each a number or
// three; every key optional, 0 by default): homogeneous, or with "grid" (an OpenVDB file, with_grid only) the
// coefficients at density 1 of a heterogeneous medium (grid_medium.h) whose densities the grid holds.
std::shared_ptr<const Medium> load_medium(const json& m, const std::string& pointer, const SceneLoadOptions& options,
                                          bool with_grid) {
  if (!m.is_object()) throw SceneError(pointer, "must be an object with \"sigma_a\", \"sigma_s\" and \"g\"");
  const bool grid = m.contains("grid");
  if (grid && !with_grid)
    throw SceneError(at(pointer, "grid"),
                     "a medium from a grid needs a boundary: give it to an object (objects[].medium), not the scene");
  check_medium_keys(m, pointer, grid);
  const Rgb sigma_a = params::rgb(m, "sigma_a", pointer, Rgb(0), 0.0f, 1e9f);
  const Rgb sigma_s = params::rgb(m, "sigma_s", pointer, Rgb(0), 0.0f, 1e9f);
  float g = 0;
  if (auto it = m.find("g"); it != m.end()) {
    g = static_cast<float>(finite_number(*it, at(pointer, "g")));
    // |g| = 1 is a delta phase function (no scattering at all, or a mirror), not a Henyey–Greenstein lobe.
    if (!(std::abs(g) < 1)) throw SceneError(at(pointer, "g"), "must lie strictly between -1 and 1");
  }
  if (!grid) return std::make_shared<HomogeneousMedium>(sigma_a, sigma_s, g);
  GridMediumDesc desc;
  desc.sigma_a = sigma_a;
  desc.sigma_s = sigma_s;
  desc.g = g;
  return grid_medium_of(m, pointer, options, desc);
}

// A camera that sees the whole of `b` from the front and a little above.
CameraDesc framing_camera(const Bounds& b) {
  CameraDesc desc;
  desc.fov_deg = 40;
  Vec3 c = b.empty() ? Vec3(0) : b.center();
  float r = b.empty() ? 1.0f : std::max(b.radius(), 1e-3f);
  float dist = r / std::sin(desc.fov_deg * kPi / 360.0f) * 1.1f;
  desc.to = c;
  desc.from = c + normalize(Vec3(0, 0.25f, 1)) * dist;
  desc.up = Vec3(0, 1, 0);
  return desc;
}

// Refuses geometry that is not a finite number or lies beyond kMaxSceneCoordinate (scene.h), whichever shapes and
// assets it came from: such a scene would make rays Embree cannot trace.
void check_extent(const Scene& scene, const std::string& pointer) {
  bool finite = true;
  const Bounds b = scene.geometry_bounds(&finite);
  if (!finite) throw SceneError(pointer, "the scene's geometry holds a coordinate that is not a finite number");
  if (b.empty()) return;
  const float reach = std::max(
      {std::abs(b.lo.x), std::abs(b.lo.y), std::abs(b.lo.z), std::abs(b.hi.x), std::abs(b.hi.y), std::abs(b.hi.z)});
  if (!(reach <= kMaxSceneCoordinate)) {
    char text[96];
    std::snprintf(text, sizeof text, "the scene's geometry reaches %.3g units from the origin, beyond the %.3g",
                  static_cast<double>(reach), static_cast<double>(kMaxSceneCoordinate));
    throw SceneError(pointer, std::string(text) + " a scene may span (is the asset corrupt or in the wrong units?)");
  }
}

}  // namespace

std::shared_ptr<Scene> load_scene(const json& doc, const std::string& pointer, const SceneLoadOptions& options) {
  if (!doc.is_object()) throw SceneError(pointer, "the scene must be an object");
  auto scene = std::make_shared<Scene>();
  MaterialContext mctx;
  mctx.asset_root = options.asset_root;
  // A scene that will not be rendered (a job checked at submission) reads its images' headers, not their pixels.
  mctx.headers_only = !options.build;

  // Materials by name.
  std::map<std::string, uint32_t> names;
  if (auto it = doc.find("materials"); it != doc.end()) {
    const std::string mp = at(pointer, "materials");
    if (!it->is_object()) throw SceneError(mp, "must be an object mapping names to materials");
    std::vector<std::pair<std::string, const json*>> items;
    for (const auto& [name, m] : it->items()) {
      if (name.empty() || name.size() > 256) throw SceneError(mp, "material names must have 1 to 256 characters");
      items.emplace_back(name, &m);
    }
    // Made side by side: a material reads its image files as it is made (decoding them is most of such a scene's
    // load). Of several bad materials, the first in document order is reported (run_in_parallel's rule).
    std::vector<std::unique_ptr<Material>> made(items.size());
    run_in_parallel(items.size(), [&](size_t i) {
      if (options.stop.stop_requested()) throw LoadStopped();
      made[i] = MaterialRegistry::builtin().create(*items[i].second, at(mp, items[i].first), mctx);
    });
    for (size_t i = 0; i < items.size(); ++i) {
      names[items[i].first] = static_cast<uint32_t>(scene->materials.size());
      scene->materials.push_back(std::move(made[i]));
      scene->material_names.push_back(items[i].first);
    }
  }

  // A glTF asset: its nodes, materials (unless the job overrides them by name), cameras and lights.
  GltfImport gltf;
  bool has_gltf = false;
  if (auto it = doc.find("gltf"); it != doc.end()) {
    const std::string gp = at(pointer, "gltf");
    GltfImportOptions gopts;
    gopts.material_overrides = names;
    gopts.max_triangles = options.max_triangles;
    gopts.max_vertices = options.max_gltf_vertices;
    gopts.headers_only = !options.build;
    gopts.max_instances = options.max_gltf_instances;
    gopts.stop = options.stop;
    if (auto v = doc.find("gltf_variant"); v != doc.end()) {
      gopts.variant_pointer = at(pointer, "gltf_variant");
      if (!v->is_string() || v->get<std::string>().empty() || v->get<std::string>().size() > 256)
        throw SceneError(gopts.variant_pointer, "must be a variant's name (1 to 256 characters)");
      gopts.variant = v->get<std::string>();
    }
    // A still at scene.time seconds of the animation scene.animation chooses (by name or index; default the first).
    // Neither given: the nodes as the asset states them.
    if (auto a = doc.find("animation"); a != doc.end()) {
      gopts.animate = true;
      gopts.animation_pointer = at(pointer, "animation");
      if (a->is_string() && !a->get<std::string>().empty() && a->get<std::string>().size() <= 256)
        gopts.animation_name = a->get<std::string>();
      else if (a->is_number_integer() && a->get<int64_t>() >= 0 && a->get<int64_t>() <= 1'000'000)
        gopts.animation_index = static_cast<int>(a->get<int64_t>());
      else
        throw SceneError(gopts.animation_pointer, "must be an animation's name (1 to 256 characters) or index");
    }
    if (auto t = doc.find("time"); t != doc.end()) {
      gopts.animate = true;
      if (!t->is_number() || !std::isfinite(t->get<double>()) || std::abs(t->get<double>()) > 1e9)
        throw SceneError(at(pointer, "time"), "must be a time in seconds (at most 1e9 in magnitude)");
      gopts.time = t->get<double>();
    }
    // Added to the time of every frame of a range (frames.h: frame_scene folds it into scene.time).
    if (auto t = doc.find("time_offset"); t != doc.end())
      if (!t->is_number() || !std::isfinite(t->get<double>()) || std::abs(t->get<double>()) > 1e9)
        throw SceneError(at(pointer, "time_offset"), "must be a time in seconds (at most 1e9 in magnitude)");
    if (!options.frames_pointer.empty()) {
      gopts.animate = true;
      gopts.frames_pointer = options.frames_pointer;
    }
    if (gopts.animate)
      gopts.shutter_times = options.shutter_times;
    else if (!options.shutter_times.empty())
      scene->warnings.push_back(
          "render.shutter blurs nothing: the asset is rendered as it is stated, not animated (scene.time or "
          "scene.animation poses it by its animation)");
    gltf = import_gltf(resolve(options, *it, gp), gp, *scene, gopts);
    has_gltf = true;
    for (const std::string& w : gltf.warnings) scene->warnings.push_back(w);
  }

  if (!has_gltf && doc.contains("gltf_variant"))
    throw SceneError(at(pointer, "gltf_variant"), "a variant is chosen only for a glTF asset (scene.gltf)");
  if (!has_gltf && !options.shutter_times.empty())
    scene->warnings.push_back("render.shutter blurs nothing: only a glTF asset's animation moves (scene.gltf)");
  if (!has_gltf && !options.frames_pointer.empty())
    throw SceneError(options.frames_pointer, "a frame range renders a glTF asset's animation (scene.gltf)");
  for (const char* key : {"animation", "time", "time_offset"})
    if (!has_gltf && doc.contains(key))
      throw SceneError(at(pointer, key), "animations are posed only for a glTF asset (scene.gltf)");

  // Objects.
  static const json kNoObjects = json::array();
  const json& objects = has_gltf && !doc.contains("objects") ? kNoObjects : require(doc, "objects", pointer);
  const std::string op = at(pointer, "objects");
  if (!objects.is_array()) throw SceneError(op, "must be an array of objects");
  size_t triangles = scene->triangle_count();
  const json* material_docs = nullptr;
  if (auto it = doc.find("materials"); it != doc.end()) material_docs = &*it;
  for (size_t i = 0; i < objects.size(); ++i) {
    if (options.stop.stop_requested()) throw LoadStopped();
    const json& obj = objects[i];
    const std::string p = at(op, i);
    if (!obj.is_object()) throw SceneError(p, "must be an object");
    const json& shape = require(obj, "shape", p);
    if (!shape.is_string()) throw SceneError(at(p, "shape"), "must be \"mesh\", \"sphere\" or \"rectangle\"");
    uint32_t material = material_index(obj, p, names);
    const std::string s = shape.get<std::string>();
    // The object's name, for Cryptomatte's object mattes: its own, or where it stands in the document.
    std::string object_name = "objects[" + std::to_string(i) + "]";
    if (auto n = obj.find("name"); n != obj.end()) {
      if (!n->is_string() || n->get_ref<const std::string&>().empty() || n->get_ref<const std::string&>().size() > 256)
        throw SceneError(at(p, "name"), "must be a name of 1 to 256 characters");
      object_name = n->get<std::string>();
    }
    const size_t meshes_before = scene->meshes.size(), spheres_before = scene->spheres.size();
    if (auto m = obj.find("medium"); m != obj.end()) {
      // The medium fills the shape; its boundary is the object's material, which a path crosses to get in and out:
      // a dielectric (refracting) or an interface (index-matched, not drawn). The object gets a material of its own
      // with that interior (materials are shared by name, media are per object).
      const std::string mp = at(p, "medium");
      if (s == "rectangle")
        throw SceneError(mp, "a rectangle encloses no volume: a medium needs a closed shape (a sphere or a mesh)");
      const std::string& name = obj["material"].get_ref<const std::string&>();
      const json& material_doc = (*material_docs)[name];
      const std::string type = material_doc.value("type", std::string());
      if (scene->materials[material]->interior() && !material_doc.contains("attenuation_color") &&
          !material_doc.contains("attenuation_distance"))
        throw SceneError(mp, "the material \"" + name +
                                 "\" has subsurface parameters, an interior medium of its own: give the object a "
                                 "medium or the material subsurface parameters, not both");
      if (type != "dielectric" && type != "interface")
        throw SceneError(at(p, "material"),
                         "the boundary of a medium must be a \"dielectric\" or \"interface\" material; \"" + name +
                             "\" is a \"" + type + "\"");
      if (material_doc.contains("attenuation_color") || material_doc.contains("attenuation_distance"))
        throw SceneError(mp, "the material \"" + name +
                                 "\" has attenuation_color or attenuation_distance, an absorbing interior of its own: "
                                 "give the object a medium or the material an attenuation, not both");
      Material::Common enclosing;
      enclosing.interior = load_medium(*m, mp, options, true);
      material = static_cast<uint32_t>(scene->materials.size());
      scene->materials.push_back(MaterialRegistry::builtin().create(material_doc, at(at(pointer, "materials"), name),
                                                                    mctx, std::move(enclosing)));
      scene->material_names.push_back(name);
    }
    if (s == "sphere") {
      Sphere sphere;
      sphere.center = vec3_key(obj, "center", p);
      sphere.radius = number_key(obj, "radius", p, 1, 0, 1e9, true);
      if (!obj.contains("radius")) throw SceneError(at(p, "radius"), "\"radius\" is required");
      sphere.material = material;
      scene->spheres.push_back(sphere);
    } else if (s == "mesh") {
      load_mesh(obj, p, material, *scene, &triangles, options.max_triangles);
    } else if (s == "rectangle") {
      load_rectangle(obj, p, material, *scene);
    } else {
      throw SceneError(at(p, "shape"), "unknown shape \"" + s + "\"; expected \"mesh\", \"sphere\" or \"rectangle\"");
    }
    for (size_t m = meshes_before; m < scene->meshes.size(); ++m) scene->meshes[m].name = object_name;
    for (size_t k = spheres_before; k < scene->spheres.size(); ++k) scene->spheres[k].name = object_name;
  }

  // The camera: the document's, a glTF camera chosen by index or name, the asset's first camera, or one that
  // frames the asset.
  const std::string cp = at(pointer, "camera");
  auto cam_it = doc.find("camera");
  if (has_gltf && (cam_it == doc.end() || (cam_it->is_object() && cam_it->contains("gltf")))) {
    if (cam_it != doc.end()) {
      const json& sel = (*cam_it)["gltf"];
      const GltfCamera* found = nullptr;
      if (sel.is_number_integer() && sel.get<int64_t>() >= 0 &&
          sel.get<int64_t>() < static_cast<int64_t>(gltf.cameras.size()))
        found = &gltf.cameras[sel.get<size_t>()];
      if (sel.is_string())
        for (const GltfCamera& c : gltf.cameras)
          if (c.name == sel.get<std::string>()) found = &c;
      if (!found)
        throw SceneError(at(cp, "gltf"),
                         "no such camera in the glTF asset (it has " + std::to_string(gltf.cameras.size()) + ")");
      scene->camera = found->desc;
      scene->camera_motion = found->motion;
    } else if (!gltf.cameras.empty()) {
      scene->camera = gltf.cameras[0].desc;
      scene->camera_motion = gltf.cameras[0].motion;
    } else {
      Bounds b = gltf.bounds;
      for (const Sphere& sp : scene->spheres) {
        b.extend(sp.center - Vec3(sp.radius));
        b.extend(sp.center + Vec3(sp.radius));
      }
      for (const Mesh& m : scene->meshes)
        for (const Vec3& p : m.positions) b.extend(p);
      scene->camera = framing_camera(b);
    }
  } else {
    scene->camera = load_camera(require(doc, "camera", pointer), cp);
  }

  if (auto it = doc.find("environment"); it != doc.end()) {
    const std::string ep = at(pointer, "environment");
    if (!it->is_object()) throw SceneError(ep, "must be an object");
    scene->environment.intensity = number_key(*it, "intensity", ep, 1, 0, 1e9);
    if (auto m = it->find("map"); m != it->end()) {
      // An equirectangular HDR/EXR map; "color" tints it.
      std::filesystem::path file = resolve(options, *m, at(ep, "map"));
      try {
        if (options.build) {
          scene->environment.map = EnvironmentMap::load(file.string());
        } else {
          EnvironmentMap::check(file.string());
          scene->environment.map = std::make_shared<EnvironmentMap>(2, 1, std::vector<float>(6, 1.0f));  // a stand-in
        }
      } catch (const std::exception& e) {
        throw SceneError(at(ep, "map"), std::string("cannot read the environment map: ") + e.what());
      }
      scene->environment.color = params::rgb(*it, "color", ep, Rgb(1), 0.0f, 1e9f);
      scene->environment.rotation_deg = number_key(*it, "rotation_deg", ep, 0, -360, 360);
    } else {
      scene->environment.color = params::rgb(*it, "color", ep, Rgb(0), 0.0f, 1e9f);
    }
  }

  std::vector<PunctualLight> punctual = gltf.lights;
  if (auto it = doc.find("lights"); it != doc.end()) {
    const std::string lp = at(pointer, "lights");
    if (!it->is_array()) throw SceneError(lp, "must be an array of lights");
    for (size_t i = 0; i < it->size(); ++i) {
      const json& l = (*it)[i];
      const std::string p = at(lp, i);
      if (!l.is_object()) throw SceneError(p, "must be an object");
      PunctualLight light;
      std::string type = l.value("type", std::string());
      if (type == "point") {
        light.kind = PunctualLight::Kind::kPoint;
        light.position = vec3_key(l, "position", p);
        light.intensity = params::rgb(l, "intensity", p, Rgb(1), 0.0f, 1e12f);
      } else if (type == "spot") {
        light.kind = PunctualLight::Kind::kSpot;
        light.position = vec3_key(l, "position", p);
        light.direction = normalize(vec3_key(l, "direction", p));
        light.intensity = params::rgb(l, "intensity", p, Rgb(1), 0.0f, 1e12f);
        float inner = number_key(l, "inner_cone_deg", p, 0, 0, 90);
        float outer = number_key(l, "outer_cone_deg", p, 45, 0, 90, true);
        if (inner > outer) throw SceneError(at(p, "inner_cone_deg"), "must not exceed outer_cone_deg");
        light.cos_inner = std::cos(inner * kPi / 180);
        light.cos_outer = std::cos(outer * kPi / 180);
      } else if (type == "directional") {
        light.kind = PunctualLight::Kind::kDirectional;
        light.direction = vec3_key(l, "direction", p);
        if (!(length(light.direction) > 0)) throw SceneError(at(p, "direction"), "must not be the zero vector");
        light.direction = normalize(light.direction);
        light.intensity = params::rgb(l, "irradiance", p, Rgb(1), 0.0f, 1e12f);
      } else {
        throw SceneError(at(p, "type"), "must be \"point\", \"spot\" or \"directional\"");
      }
      punctual.push_back(light);
    }
  }

  if (auto it = doc.find("medium"); it != doc.end()) {
    scene->medium = load_medium(*it, at(pointer, "medium"), options, false);
    // Light from infinitely far (the environment, directional lights) crosses an infinite stretch of the medium: in
    // a channel that interacts at all none of it arrives.
    MediumRng rng;
    const Rgb far = scene->medium->transmittance(Ray{}, kInfinity, rng);
    const bool directional = std::any_of(punctual.begin(), punctual.end(), [](const PunctualLight& l) {
      return l.kind == PunctualLight::Kind::kDirectional;
    });
    if ((!scene->environment.black() || directional) && is_black(far))
      scene->warnings.push_back(
          "the medium around the objects fills all space: no light from the environment or from directional lights "
          "crosses it (light it with lights at a finite distance)");
  }

  if (scene->meshes.empty() && scene->spheres.empty() && scene->environment.black() && punctual.empty())
    throw SceneError(op, "the scene has nothing to render");
  // glTF assets usually rely on the viewer's image-based light, and their emissive materials are decorative
  // (screens, LEDs) rather than illumination. With no environment in the job and no punctual lights, light the asset
  // as a viewer would, and say so.
  if (has_gltf && !doc.contains("environment") && punctual.empty()) {
    scene->environment.color = Rgb(1);
    scene->notes.push_back(
        "the scene has no environment or punctual light; a uniform white environment of "
        "radiance 1 was added");
  }
  if (options.stop.stop_requested()) throw LoadStopped();
  check_extent(*scene, pointer);
  tidy_warnings(&scene->warnings);
  if (options.build) scene->finalize_with_lights(punctual);
  return scene;
}

}  // namespace tessera
