#include "renderer/scene.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>

namespace tessera {

namespace {

// The last line tidy_warnings writes, "and <n> more warnings": true, with n, for such a line.
bool more_warnings_line(const std::string& w, size_t* n) {
  static const std::string kHead = "and ", kTail = " more warnings";
  if (w.size() <= kHead.size() + kTail.size() || w.compare(0, kHead.size(), kHead) != 0 ||
      w.compare(w.size() - kTail.size(), kTail.size(), kTail) != 0)
    return false;
  const std::string digits = w.substr(kHead.size(), w.size() - kHead.size() - kTail.size());
  if (digits.size() > 18 || digits.find_first_not_of("0123456789") != std::string::npos) return false;
  *n = std::stoull(digits);
  return true;
}

}  // namespace

void Scene::finalize() {
  finalize_with_lights({});
}

void Scene::finalize_with_lights(const std::vector<PunctualLight>& punctual) {
  auto start = std::chrono::steady_clock::now();
  bounds_ = geometry_bounds();
  // Embree reads vertex buffers with 16-byte loads: keep 4 bytes readable past the last vertex.
  moving_ = !camera_motion.empty();
  for (Mesh& mesh : meshes) {
    mesh.positions.reserve(mesh.positions.size() + 1);
    for (std::vector<Vec3>& step : mesh.motion_positions) step.reserve(step.size() + 1);
    moving_ = moving_ || mesh.moves();
  }
  std::vector<const Material*> material_ptrs;
  dispersive_ = false;
  index_matched_ = false;
  for (const auto& m : materials) {
    material_ptrs.push_back(m.get());
    dispersive_ = dispersive_ || m->dispersive();
    index_matched_ = index_matched_ || m->index_matched();
  }
  scattering_ = has_scattering_media();
  accel_.build(meshes, spheres, groups, instances, material_ptrs);
  lights_.build(meshes, spheres, materials, environment, bounds_, punctual);
  // Record each emitter's light index on its geometry, in the order LightSet::build enumerates them.
  uint32_t next = 0;
  for (Mesh& mesh : meshes) {
    if (mesh.prototype || !materials[mesh.material]->emissive()) continue;
    mesh.first_light = next;
    next += static_cast<uint32_t>(mesh.triangle_count());
  }
  for (Sphere& s : spheres) {
    if (!materials[s.material]->emissive()) continue;
    s.light = next++;
  }
  build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

Bounds Scene::geometry_bounds(bool* finite) const {
  Bounds b;
  bool ok = true;
  auto extend = [&](const Vec3& p) {
    ok = ok && std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
    b.extend(p);
  };
  for (const Mesh& mesh : meshes)
    if (!mesh.prototype) {
      for (const Vec3& p : mesh.positions) extend(p);
      for (const std::vector<Vec3>& step : mesh.motion_positions)
        for (const Vec3& p : step) extend(p);
    }
  for (const Instance& inst : instances) {
    for (uint32_t m : groups.at(inst.group).meshes) {
      Bounds local;
      for (const Vec3& p : meshes[m].positions) {
        ok = ok && std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
        local.extend(p);
      }
      if (local.empty()) continue;
      for (int c = 0; c < 8; ++c)
        extend(inst.to_world.point(
            Vec3(c & 1 ? local.hi.x : local.lo.x, c & 2 ? local.hi.y : local.lo.y, c & 4 ? local.hi.z : local.lo.z)));
    }
  }
  for (const Sphere& s : spheres) {
    ok = ok && std::isfinite(s.radius);
    extend(s.center - Vec3(s.radius));
    extend(s.center + Vec3(s.radius));
  }
  if (finite) *finite = ok;
  return b;
}

void tidy_warnings(std::vector<std::string>* warnings) {
  std::set<std::string> seen;
  std::vector<std::string> kept;
  size_t more = 0;
  for (std::string& w : *warnings) {
    size_t counted = 0;
    if (more_warnings_line(w, &counted)) {  // what an earlier tidy left out
      more += counted;
      continue;
    }
    if (!seen.insert(w).second) continue;
    if (kept.size() < kMaxWarnings)
      kept.push_back(std::move(w));
    else
      ++more;
  }
  if (more > 0) kept.push_back("and " + std::to_string(more) + " more warnings");
  *warnings = std::move(kept);
}

std::vector<std::string> Scene::object_names() const {
  std::vector<std::string> names;
  names.reserve(meshes.size() + spheres.size() + instances.size());
  auto add = [&](const std::string& name) {
    names.push_back(name.empty() ? "object " + std::to_string(names.size()) : name);
  };
  for (const Mesh& m : meshes) add(m.name);
  for (const Sphere& s : spheres) add(s.name);
  for (const Instance& i : instances) add(i.name);
  return names;
}

size_t Scene::triangle_count() const {
  size_t n = 0;
  for (const Mesh& m : meshes)
    if (!m.prototype) n += m.triangle_count();
  for (const Instance& inst : instances)
    for (uint32_t m : groups[inst.group].meshes) n += meshes[m].triangle_count();
  return n;
}

size_t Scene::unique_triangle_count() const {
  size_t n = 0;
  for (const Mesh& m : meshes) n += m.triangle_count();
  return n;
}

bool Scene::intersect(const Ray& ray, SurfaceInteraction* si, const RayCone* cone) const {
  RayHit hit;
  if (!accel_.intersect(ray, &hit)) return false;
  interaction(ray, hit, si, cone);
  return true;
}

void Scene::interaction(const Ray& ray, const RayHit& hit, SurfaceInteraction* si, const RayCone* cone) const {
  si->t = hit.t;
  ShadingPoint& sp = si->sp;
  sp.p = ray.origin + ray.dir * hit.t;
  float uv_per_world = 0;  // how many uv units a unit of length on the surface spans (the square root of areas' ratio)
  if (hit.is_sphere) {
    const Sphere& s = spheres[hit.object];
    Vec3 n = normalize(sp.p - s.center);
    // Re-project onto the surface to keep ray origins from drifting inside or outside.
    sp.p = s.center + n * s.radius;
    sp.ng = n;
    sp.frame = Frame::from_normal_tangent(n, Vec3(-n.z, 0, n.x));
    float phi = fast_atan2(n.z, n.x);
    sp.uv = Vec2(0.5f + phi * kInv2Pi, fast_atan2(std::sqrt(n.x * n.x + n.z * n.z), n.y) * kInvPi);
    sp.uv1 = sp.uv;
    // u spans 2 pi r and v spans pi r of length.
    si->material = materials[s.material].get();
    si->material_index = s.material;
    si->object = static_cast<uint32_t>(meshes.size()) + hit.object;
    if (si->material->reads_textures()) uv_per_world = 1 / (std::sqrt(2.0f) * kPi * s.radius);
    sp.vertex_color = Rgb(1);
    si->light = si->material->emissive() ? s.light : kNoLight;
  } else {
    const Mesh& mesh = meshes[hit.object];
    const Instance* inst = hit.instance == kNoInstance ? nullptr : &instances[hit.instance];
    const uint32_t* idx = &mesh.indices[3 * hit.prim_id];
    float b1 = hit.u, b2 = hit.v, b0 = 1 - b1 - b2;
    // Where the triangle is at the ray's time (a moving mesh's, as Embree intersected it).
    Vec3 p0 = mesh.position_at(idx[0], ray.time);
    Vec3 p1 = mesh.position_at(idx[1], ray.time);
    Vec3 p2 = mesh.position_at(idx[2], ray.time);
    if (inst) {
      p0 = inst->to_world.point(p0);
      p1 = inst->to_world.point(p1);
      p2 = inst->to_world.point(p2);
    }
    Vec3 e1 = p1 - p0, e2 = p2 - p0;
    Vec3 ng = cross(e1, e2);
    float ng_len = length(ng);
    ng = ng_len > 0 ? ng * (1 / ng_len) : Vec3(0, 0, 1);
    if (inst && inst->mirrored) ng = -ng;  // glTF: a mirroring transform makes the clockwise face the front
    sp.ng = ng;
    Vec3 ns = ng;
    if (!mesh.normals.empty()) {
      Vec3 n = mesh.normal_at(idx[0], ray.time) * b0 + mesh.normal_at(idx[1], ray.time) * b1 +
               mesh.normal_at(idx[2], ray.time) * b2;
      if (inst) n = inst->normal_to_world.vector(n);
      float len2 = length_squared(n);
      if (len2 > 0 && std::isfinite(len2)) {
        ns = n / std::sqrt(len2);
        if (dot(ns, ng) < 0) sp.ng = -ng;  // shading normals define the front side
      }
    }
    Vec2 uv0(0, 0), uv1(1, 0), uv2(1, 1);
    if (!mesh.uvs.empty()) {
      uv0 = mesh.uvs[idx[0]];
      uv1 = mesh.uvs[idx[1]];
      uv2 = mesh.uvs[idx[2]];
    }
    sp.uv = uv0 * b0 + uv1 * b1 + uv2 * b2;
    // The uv edges: their cross product is twice the triangle's uv area (for the footprint and the tangent).
    const Vec2 d1 = uv1 - uv0, d2 = uv2 - uv0;
    const float uv_det = d1.x * d2.y - d1.y * d2.x;
    const Material* material = materials[mesh.material].get();
    si->material_index = mesh.material;
    si->object = inst ? static_cast<uint32_t>(meshes.size() + spheres.size()) + hit.instance : hit.object;
    if (cone && ng_len > 0 && material->reads_textures()) uv_per_world = std::sqrt(std::abs(uv_det) / ng_len);
    sp.uv1 = mesh.uvs1.empty() ? sp.uv : mesh.uvs1[idx[0]] * b0 + mesh.uvs1[idx[1]] * b1 + mesh.uvs1[idx[2]] * b2;
    // Tangent: from the mesh when given, else along dp/du (with the handedness of dp/dv); none is needed for an
    // isotropic material without a normal map.
    const bool needs_tangent = !material->isotropic() || material->normal_map() || material->coat_normal_map();
    Vec3 tangent;
    if (!needs_tangent) {
      sp.frame = Frame::from_normal(ns);
    } else if (!mesh.tangents.empty()) {
      tangent = mesh.tangents[idx[0]] * b0 + mesh.tangents[idx[1]] * b1 + mesh.tangents[idx[2]] * b2;
      if (inst) tangent = inst->to_world.vector(tangent);
      sp.tangent_sign = mesh.tangent_signs.empty() || mesh.tangent_signs[idx[0]] >= 0 ? 1.0f : -1.0f;
    } else {
      if (std::abs(uv_det) > 1e-12f) {
        tangent = (e1 * d2.y - e2 * d1.y) / uv_det;
        Vec3 bitangent = (e2 * d1.x - e1 * d2.x) / uv_det;
        sp.tangent_sign = dot(cross(ns, tangent), bitangent) < 0 ? -1.0f : 1.0f;
      } else {
        tangent = e1;
        sp.tangent_sign = 1;
      }
    }
    if (needs_tangent) sp.frame = Frame::from_normal_tangent(ns, tangent);
    sp.vertex_color =
        mesh.colors.empty() ? Rgb(1) : mesh.colors[idx[0]] * b0 + mesh.colors[idx[1]] * b1 + mesh.colors[idx[2]] * b2;
    si->material = material;
    si->light = si->material->emissive() ? mesh.first_light + hit.prim_id : kNoLight;
  }
  sp.front_face = dot(ray.dir, sp.ng) < 0;
  sp.uv_footprint = 0;
  if (cone && uv_per_world > 0) {
    // The cone's width where it hits, widened as the surface turns away from it. Its footprint is an ellipse, the
    // width across and width / cos along the turn; an isotropic filter takes the width of the circle of the same area,
    // width / sqrt(cos) (the major axis, as Akenine-Möller et al. 2019 take, blurs across by up to 8x at grazing
    // angles: measured by bench/texture_lod.sh), at most 8x.
    const float dir_len = length(ray.dir);
    const float cos_hit = std::abs(dot(ray.dir, sp.ng)) / dir_len;
    sp.uv_footprint = cone->width_at(hit.t * dir_len) / std::sqrt(std::max(cos_hit, 1.0f / 64)) * uv_per_world;
  }
  sp.coat_normal = Vec3(0, 0, 0);
  if (si->material->coat_normal_map()) {
    // From the frame before the base's normal map bends it.
    const Vec3 n = mapped_normal(*si->material->coat_normal_map(), si->material->coat_normal_scale(), sp);
    if (length_squared(n) > 0) sp.coat_normal = keep_reflection_above_surface(n, sp.ng, -ray.dir);
  }
  if (si->material->normal_map()) apply_normal_map(*si->material, -ray.dir, &sp);
}

Vec3 keep_reflection_above_surface(const Vec3& n, const Vec3& ng, const Vec3& wo_in) {
  const float wo_len2 = length_squared(wo_in);
  if (!(wo_len2 > 0)) return n;
  const Vec3 wo = wo_in / std::sqrt(wo_len2);
  // Work on the viewer's side of the surface (a path may arrive from behind: inside glass, a double-sided leaf).
  const float side = dot(wo, ng) < 0 ? -1.0f : 1.0f;
  const Vec3 g = ng * side, ns = n * side;
  const float wo_g = dot(wo, g);
  if (!(wo_g > 0)) return n;
  // The threshold: a little above the horizon (sin of 3 degrees; Cycles takes 0.01, but GGX's long tail then puts 7 %
  // of even tessera's smoothest lobe, alpha 0.002, under the surface, where 3 degrees leaves 0.3 %), and below the
  // viewer's own elevation at grazing views.
  const float threshold = std::min(0.9f * wo_g, 0.05f);
  const Vec3 r = ns * (2 * dot(ns, wo)) - wo;
  if (dot(ns, wo) > 0 && dot(r, g) >= threshold) return n;
  // The bent reflection: r's direction along the surface (or, when r has none, the shading normal's, or the
  // viewer's mirrored), raised to the threshold's elevation; the normal that reflects wo into it is their half vector.
  Vec3 along = r - g * dot(r, g);
  if (!(length_squared(along) > 1e-12f)) along = ns - g * dot(ns, g);
  if (!(length_squared(along) > 1e-12f)) along = g * dot(wo, g) - wo;
  if (!(length_squared(along) > 1e-12f)) return n;
  const Vec3 bent = normalize(along) * std::sqrt(1 - threshold * threshold) + g * threshold;
  return normalize(wo + bent) * side;
}

Vec3 mapped_normal(const Texture& map, float scale, const ShadingPoint& sp) {
  // glTF 3.9.3: the texel maps [0,1] to [-1,1]; x and y are scaled; the result is in the tangent frame
  // (tangent, bitangent = sign * n x t, normal).
  Rgb t = map.eval(sp);
  Vec3 local((2 * t.x - 1) * scale, (2 * t.y - 1) * scale, 2 * t.z - 1);
  const Frame& f = sp.frame;
  Vec3 n = f.s * local.x + f.t * (local.y * sp.tangent_sign) + f.n * local.z;
  float len2 = length_squared(n);
  if (!(len2 > 1e-12f) || !std::isfinite(len2)) return Vec3(0, 0, 0);
  n = n / std::sqrt(len2);
  // A perturbed normal must stay on the surface's side, or shading would see light from behind.
  if (dot(n, sp.ng) <= 1e-3f) return Vec3(0, 0, 0);
  return n;
}

void apply_normal_map(const Material& material, const Vec3& wo, ShadingPoint* sp) {
  const Vec3 n = mapped_normal(*material.normal_map(), material.normal_scale(), *sp);
  if (length_squared(n) > 0)
    sp->frame = Frame::from_normal_tangent(keep_reflection_above_surface(n, sp->ng, wo), sp->frame.s);
}

bool Scene::has_scattering_media() const {
  if (medium && medium->scatters()) return true;
  return std::any_of(materials.begin(), materials.end(),
                     [](const auto& m) { return m->interior() && m->interior()->scatters(); });
}

Vec3 offset_ray_origin(const Vec3& p, const Vec3& ng, const Vec3& dir) {
  // An offset proportional to the coordinates' magnitude covers float rounding of the hit point.
  float scale = 1e-4f * std::max(1.0f, std::max(std::abs(p.x), std::max(std::abs(p.y), std::abs(p.z))));
  Vec3 offset = ng * scale;
  return dot(dir, ng) >= 0 ? p + offset : p - offset;
}

}  // namespace tessera
