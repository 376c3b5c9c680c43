#include "renderer/lights.h"

#include "renderer/environment.h"
#include "renderer/geometry.h"
#include "renderer/interaction.h"
#include "renderer/material/material.h"

namespace tessera {

namespace {

struct TrianglePoints {
  Vec3 a, b, c;
};
TrianglePoints triangle(const Mesh& mesh, uint32_t prim) {
  return {mesh.positions[mesh.indices[3 * prim]], mesh.positions[mesh.indices[3 * prim + 1]],
          mesh.positions[mesh.indices[3 * prim + 2]]};
}

// Texture coordinates at barycentrics (b1, b2) of a mesh triangle, for textured emission.
void triangle_uv(const Mesh& mesh, uint32_t prim, float b1, float b2, ShadingPoint* sp) {
  if (mesh.uvs.empty()) return;
  const uint32_t* idx = &mesh.indices[3 * prim];
  sp->uv = mesh.uvs[idx[0]] * (1 - b1 - b2) + mesh.uvs[idx[1]] * b1 + mesh.uvs[idx[2]] * b2;
  sp->uv1 = sp->uv;
}

float emitted_power(const Rgb& average_radiance, float area, bool one_sided) {
  return luminance(average_radiance) * area * kPi * (one_sided ? 1.0f : 2.0f);
}

}  // namespace

void LightSet::build(const std::vector<Mesh>& meshes, const std::vector<Sphere>& spheres,
                     const std::vector<std::unique_ptr<Material>>& materials, const Environment& environment,
                     const Bounds& bounds, const std::vector<PunctualLight>& punctual) {
  meshes_ = &meshes;
  spheres_ = &spheres;
  materials_ = &materials;
  env_ = &environment;
  entries_.clear();
  triangles_.clear();
  punctual_ = punctual;
  environment_ = kNoLight;
  scene_radius_ = std::max(bounds.radius(), 1e-3f);
  scene_center_ = bounds.empty() ? Vec3(0) : bounds.center();
  std::vector<float> power;
  for (uint32_t m = 0; m < (*meshes_).size(); ++m) {
    const Mesh& mesh = (*meshes_)[m];
    const Material& mat = *(*materials_)[mesh.material];
    if (mesh.prototype || !mat.emissive()) continue;
    for (uint32_t t = 0; t < mesh.triangle_count(); ++t) {
      TrianglePoints tp = triangle(mesh, t);
      const Vec3 c = cross(tp.b - tp.a, tp.c - tp.a);
      float area = 0.5f * length(c);
      // Degenerate triangles keep their slot (light indices follow triangle order) but are never chosen.
      triangles_.resize(entries_.size());
      triangles_.push_back({tp.a, tp.b - tp.a, tp.c - tp.a, area > 0 ? c / (2 * area) : Vec3(0, 0, 1), area, &mat});
      entries_.push_back({Kind::kTriangle, m, t});
      power.push_back(area > 0 ? emitted_power(mat.emission().average(), area, mat.emission_one_sided()) : -1.0f);
    }
  }
  for (uint32_t s = 0; s < (*spheres_).size(); ++s) {
    const Sphere& sphere = (*spheres_)[s];
    const Material& mat = *(*materials_)[sphere.material];
    if (!mat.emissive()) continue;
    entries_.push_back({Kind::kSphere, s, 0});
    power.push_back(emitted_power(mat.emission().average(), 4 * kPi * sqr(sphere.radius), mat.emission_one_sided()));
  }
  for (uint32_t i = 0; i < punctual_.size(); ++i) {
    const PunctualLight& l = punctual_[i];
    entries_.push_back({Kind::kPunctual, i, 0});
    float phi = l.kind == PunctualLight::Kind::kDirectional ? kPi * sqr(scene_radius_) * luminance(l.intensity)
                                                            : 4 * kPi * luminance(l.intensity);
    power.push_back(phi);
  }
  if (!(*env_).black()) {
    environment_ = static_cast<uint32_t>(entries_.size());
    entries_.push_back({Kind::kEnvironment, 0, 0});
    // Power the environment delivers into the scene's bounding sphere.
    power.push_back(kPi * kPi * sqr(scene_radius_) * luminance((*env_).average()));
  }
  // A light whose power estimate is zero (e.g. a pure blue light has nonzero luminance, but guard anyway) keeps a
  // small share so that it is never impossible to sample.
  float total = 0;
  for (float p : power) total += std::max(p, 0.0f);
  for (float& p : power) p = p < 0 ? 0.0f : std::max(p, 1e-6f * total + 1e-30f);
  distribution_ = power.empty() ? Distribution1D() : Distribution1D(power.data(), power.size());
}

bool LightSet::sample(const Vec3& p, float u_select, Vec2 u, LightSample* out) const {
  if (entries_.empty()) return false;
  float pmf = 0;
  const uint32_t index = distribution_.sample(u_select, &pmf);
  const Entry& e = entries_[index];
  out->light = index;
  switch (e.kind) {
    case Kind::kTriangle: {
      const TriangleGeometry& tri = triangles_[index];
      const float area = tri.area;
      if (!(area > 0)) return false;
      const Material& mat = *tri.material;
      Vec2 b = sample_uniform_triangle(u);
      ShadingPoint sp;
      sp.p = tri.p0 + tri.e1 * b.x + tri.e2 * b.y;
      sp.ng = tri.n;
      sp.frame = Frame(Vec3(1, 0, 0), Vec3(0, 1, 0), tri.n);  // emission reads ng and uv only
      if (mat.emission().texture) triangle_uv((*meshes_)[e.object], e.prim, b.x, b.y, &sp);
      Vec3 d = sp.p - p;
      float dist2 = length_squared(d);
      if (!(dist2 > 0)) return false;
      float dist = std::sqrt(dist2);
      Vec3 wi = d / dist;
      float cos_light = std::abs(dot(sp.ng, wi));
      if (cos_light < 1e-7f) return false;
      out->wi = wi;
      out->dist = dist;
      out->pdf = pmf * dist2 / (cos_light * area);
      out->radiance = mat.emitted(sp, -wi);
      out->p_light = sp.p;
      out->n_light = sp.ng;
      out->delta = false;
      return true;
    }
    case Kind::kSphere: {
      const Sphere& s = (*spheres_)[e.object];
      Vec3 to_center = s.center - p;
      float dc2 = length_squared(to_center);
      float r2 = sqr(s.radius);
      ShadingPoint sp;
      if (dc2 > r2 * 1.0001f) {
        // Outside: sample the cone of directions the sphere subtends, uniformly.
        float dc = std::sqrt(dc2);
        float sin2_max = r2 / dc2;
        float cos_max = safe_sqrt(1 - sin2_max);
        Frame f = Frame::from_normal(to_center / dc);
        Vec3 wi = f.to_world(sample_uniform_cone(u, cos_max));
        // Nearest intersection with the sphere along wi (clamped to the tangent point on grazing rounding).
        float b = dot(wi, to_center);
        float disc = b * b - (dc2 - r2);
        float t = b - safe_sqrt(disc);
        sp.p = p + wi * t;
        sp.ng = normalize(sp.p - s.center);
        out->wi = wi;
        out->dist = t;
        out->pdf = pmf * uniform_cone_pdf(cos_max);
      } else {
        // Inside (or on): sample the whole surface uniformly by area.
        Vec3 n = sample_uniform_sphere(u);
        sp.p = s.center + n * s.radius;
        sp.ng = n;
        Vec3 d = sp.p - p;
        float dist2 = length_squared(d);
        if (!(dist2 > 0)) return false;
        float dist = std::sqrt(dist2);
        out->wi = d / dist;
        out->dist = dist;
        float cos_light = std::abs(dot(n, out->wi));
        if (cos_light < 1e-7f) return false;
        out->pdf = pmf * dist2 / (cos_light * 4 * kPi * r2);
      }
      sp.frame = Frame::from_normal(sp.ng);
      out->radiance = (*materials_)[s.material]->emitted(sp, -out->wi);
      out->p_light = sp.p;
      out->n_light = sp.ng;
      out->delta = false;
      return true;
    }
    case Kind::kPunctual: {
      const PunctualLight& l = punctual_[e.object];
      out->delta = true;
      out->pdf = pmf;
      if (l.kind == PunctualLight::Kind::kDirectional) {
        out->wi = -normalize(l.direction);
        out->dist = kInfinity;
        out->radiance = l.intensity;
        return true;
      }
      Vec3 d = l.position - p;
      float dist2 = length_squared(d);
      if (!(dist2 > 0)) return false;
      out->dist = std::sqrt(dist2);
      out->wi = d / out->dist;
      out->p_light = l.position;
      out->n_light = Vec3(0);
      const float falloff =
          l.kind == PunctualLight::Kind::kSpot ? spot_falloff(l, dot(-out->wi, normalize(l.direction))) : 1.0f;
      if (!(falloff > 0)) return false;
      out->radiance = l.intensity * (falloff / dist2);
      return true;
    }
    case Kind::kEnvironment: {
      float pdf_dir;
      const Vec3 wi = env_->sample_direction(u, &pdf_dir, &out->radiance);
      if (!(pdf_dir > 0)) return false;
      out->wi = wi;
      out->dist = kInfinity;
      out->pdf = pmf * pdf_dir;
      out->delta = false;
      return true;
    }
  }
  return false;
}

float LightSet::pdf_hit(const Vec3& p, const SurfaceInteraction& si) const {
  if (si.light == kNoLight || si.light >= entries_.size()) return 0;
  const Entry& e = entries_[si.light];
  float pmf = distribution_.pmf(si.light);
  if (e.kind == Kind::kTriangle) {
    const float area = triangles_[si.light].area;
    Vec3 d = si.sp.p - p;
    float dist2 = length_squared(d);
    if (!(area > 0) || !(dist2 > 0)) return 0;
    float cos_light = std::abs(dot(si.sp.ng, d)) / std::sqrt(dist2);
    if (cos_light < 1e-7f) return 0;
    return pmf * dist2 / (cos_light * area);
  }
  if (e.kind == Kind::kSphere) {
    const Sphere& s = (*spheres_)[e.object];
    Vec3 to_center = s.center - p;
    float dc2 = length_squared(to_center);
    float r2 = sqr(s.radius);
    if (dc2 > r2 * 1.0001f) {
      float cos_max = safe_sqrt(1 - r2 / dc2);
      return pmf * uniform_cone_pdf(cos_max);
    }
    Vec3 d = si.sp.p - p;
    float dist2 = length_squared(d);
    float cos_light = std::abs(dot(si.sp.ng, d)) / std::sqrt(dist2);
    if (cos_light < 1e-7f) return 0;
    return pmf * dist2 / (cos_light * 4 * kPi * r2);
  }
  return 0;
}

float spot_falloff(const PunctualLight& light, float cos_angle) {
  if (cos_angle <= light.cos_outer) return 0;
  if (cos_angle >= light.cos_inner) return 1;
  const float t = (cos_angle - light.cos_outer) / std::max(light.cos_inner - light.cos_outer, 1e-6f);
  return t * t;
}

namespace {

// A direction on the side of `n` an emitter emits to: cosine-weighted about n, and about -n too for a two-sided
// emitter (u.x picks the side). Returns the solid-angle density through `pdf`.
Vec3 sample_emitted_direction(const Vec3& n, bool one_sided, Vec2 u, float* pdf) {
  bool back = false;
  if (!one_sided) {
    back = u.x >= 0.5f;
    u.x = back ? 2 * u.x - 1 : 2 * u.x;
    u.x = std::min(u.x, 0.99999994f);
  }
  Vec3 local = sample_cosine_hemisphere(u);
  *pdf = cosine_hemisphere_pdf(local.z) * (one_sided ? 1.0f : 0.5f);
  if (back) local.z = -local.z;
  return Frame::from_normal(n).to_world(local);
}

float emitted_direction_pdf(const Vec3& n, bool one_sided, const Vec3& dir) {
  const float c = dot(n, dir);
  if (one_sided) return cosine_hemisphere_pdf(c);
  return 0.5f * cosine_hemisphere_pdf(std::abs(c));
}

}  // namespace

Rgb LightEmission::emitted(const Vec3& w) const {
  if (spot) return source * spot_falloff(*spot, dot(w, normalize(spot->direction)));
  if (one_sided && dot(w, n) <= 0) return Rgb(0);
  return source;
}

Vec3 LightSet::disc_origin(const Vec3& dir, Vec2 u) const {
  const Frame f = Frame::from_normal(dir);
  const Vec2 d = sample_concentric_disk(u) * scene_radius_;
  // The disc touches the bounding sphere on the side the light comes from: every ray starts before the scene.
  return scene_center_ - dir * scene_radius_ + f.s * d.x + f.t * d.y;
}

bool LightSet::sample_emission(float u_select, Vec2 u_pos, Vec2 u_dir, LightEmission* out) const {
  if (entries_.empty()) return false;
  float pmf = 0;
  const uint32_t index = distribution_.sample(u_select, &pmf);
  const Entry& e = entries_[index];
  *out = LightEmission();
  out->light = index;
  switch (e.kind) {
    case Kind::kTriangle: {
      const TriangleGeometry& tri = triangles_[index];
      if (!(tri.area > 0)) return false;
      const Material& mat = *tri.material;
      const Vec2 b = sample_uniform_triangle(u_pos);
      ShadingPoint sp;
      sp.p = tri.p0 + tri.e1 * b.x + tri.e2 * b.y;
      sp.ng = tri.n;
      sp.frame = Frame(Vec3(1, 0, 0), Vec3(0, 1, 0), tri.n);  // emission reads ng and uv only
      if (mat.emission().texture) triangle_uv((*meshes_)[e.object], e.prim, b.x, b.y, &sp);
      const Vec3 dir = sample_emitted_direction(tri.n, mat.emission_one_sided(), u_dir, &out->pdf_dir);
      out->ray.origin = sp.p;
      out->ray.dir = dir;
      out->n = tri.n;
      out->pdf_pos = pmf / tri.area;
      out->source = mat.emission().eval(sp);
      out->one_sided = mat.emission_one_sided();
      out->radiance = out->emitted(dir);
      break;
    }
    case Kind::kSphere: {
      const Sphere& s = (*spheres_)[e.object];
      const Material& mat = *(*materials_)[s.material];
      const Vec3 n = sample_uniform_sphere(u_pos);
      ShadingPoint sp;
      sp.p = s.center + n * s.radius;
      sp.ng = n;
      sp.frame = Frame::from_normal(n);
      const Vec3 dir = sample_emitted_direction(n, mat.emission_one_sided(), u_dir, &out->pdf_dir);
      out->ray.origin = sp.p;
      out->ray.dir = dir;
      out->n = n;
      out->pdf_pos = pmf / (4 * kPi * sqr(s.radius));
      out->source = mat.emission().eval(sp);
      out->one_sided = mat.emission_one_sided();
      out->radiance = out->emitted(dir);
      break;
    }
    case Kind::kPunctual: {
      const PunctualLight& l = punctual_[e.object];
      if (l.kind == PunctualLight::Kind::kDirectional) {
        const Vec3 dir = normalize(l.direction);
        out->ray.origin = disc_origin(dir, u_pos);
        out->ray.dir = dir;
        out->n = dir;
        out->pdf_pos = pmf * disc_pdf();
        out->pdf_dir = 1;
        out->delta_dir = true;
        out->infinite = true;
        out->radiance = l.intensity;
        break;
      }
      out->ray.origin = l.position;
      out->pdf_pos = pmf;
      out->delta_pos = true;
      if (l.kind == PunctualLight::Kind::kSpot) {
        // Uniform within the outer cone: the falloff is smooth, and the cone is usually narrow.
        const Vec3 axis = normalize(l.direction);
        out->ray.dir = Frame::from_normal(axis).to_world(sample_uniform_cone(u_dir, l.cos_outer));
        out->pdf_dir = uniform_cone_pdf(l.cos_outer);
        out->spot = &l;
      } else {
        out->ray.dir = sample_uniform_sphere(u_dir);
        out->pdf_dir = uniform_sphere_pdf();
      }
      out->source = l.intensity;
      out->radiance = out->emitted(out->ray.dir);
      break;
    }
    case Kind::kEnvironment: {
      float pdf_dir = 0;
      const Vec3 wi = env_->sample_direction(u_dir, &pdf_dir, &out->radiance);  // towards the environment
      out->ray.dir = -wi;
      out->ray.origin = disc_origin(-wi, u_pos);
      out->n = -wi;
      out->pdf_pos = pmf * disc_pdf();
      out->pdf_dir = pdf_dir;
      out->infinite = true;
      break;
    }
  }
  return out->pdf_pos > 0 && out->pdf_dir > 0 && !is_black(out->radiance);
}

void LightSet::emission_pdf(uint32_t light, const Vec3& n, const Vec3& dir, float* pdf_pos, float* pdf_dir) const {
  *pdf_pos = *pdf_dir = 0;
  if (light >= entries_.size()) return;
  const Entry& e = entries_[light];
  const float pmf = distribution_.pmf(light);
  switch (e.kind) {
    case Kind::kTriangle: {
      const TriangleGeometry& tri = triangles_[light];
      if (!(tri.area > 0)) return;
      *pdf_pos = pmf / tri.area;
      *pdf_dir = emitted_direction_pdf(n, tri.material->emission_one_sided(), dir);
      return;
    }
    case Kind::kSphere: {
      const Sphere& s = (*spheres_)[e.object];
      *pdf_pos = pmf / (4 * kPi * sqr(s.radius));
      *pdf_dir = emitted_direction_pdf(n, (*materials_)[s.material]->emission_one_sided(), dir);
      return;
    }
    case Kind::kPunctual: {
      const PunctualLight& l = punctual_[e.object];
      if (l.kind == PunctualLight::Kind::kDirectional) {
        *pdf_pos = pmf * disc_pdf();
        *pdf_dir = 0;  // a delta: no density for any given direction
        return;
      }
      *pdf_pos = pmf;
      if (l.kind == PunctualLight::Kind::kSpot)
        *pdf_dir = dot(dir, normalize(l.direction)) > l.cos_outer ? uniform_cone_pdf(l.cos_outer) : 0.0f;
      else
        *pdf_dir = uniform_sphere_pdf();
      return;
    }
    case Kind::kEnvironment: {
      *pdf_pos = pmf * disc_pdf();
      *pdf_dir = env_->direction_pdf(-dir);
      return;
    }
  }
}

bool LightSet::delta_position(uint32_t light) const {
  if (light >= entries_.size() || entries_[light].kind != Kind::kPunctual) return false;
  return punctual_[entries_[light].object].kind != PunctualLight::Kind::kDirectional;
}

bool LightSet::delta_direction(uint32_t light) const {
  if (light >= entries_.size() || entries_[light].kind != Kind::kPunctual) return false;
  return punctual_[entries_[light].object].kind == PunctualLight::Kind::kDirectional;
}

}  // namespace tessera
