// Light sampling for next-event estimation (Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed., §2.6: the
// area form of the rendering equation, and the direct illumination it isolates): emissive triangles and spheres, point
// and directional lights, and the environment, chosen in proportion to their emitted power.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "renderer/interaction.h"
#include "renderer/math.h"
#include "renderer/sampling.h"

namespace tessera {

class Material;
struct Environment;
struct Bounds;
struct Mesh;
struct Sphere;

struct PunctualLight {
  enum class Kind { kPoint, kSpot, kDirectional };
  Kind kind = Kind::kPoint;
  Vec3 position;
  Vec3 direction{0, -1, 0};  // direction the light travels (spot and directional)
  Rgb intensity{1, 1, 1};    // W/sr per channel for point and spot (candela in glTF), W/m^2 for directional (lux)
  float cos_inner = 1, cos_outer = 0;  // spot cone
};

struct LightSample {
  Rgb radiance;    // arriving at the reference point along -wi (for delta lights: intensity / dist^2 or irradiance)
  Vec3 wi;         // unit direction from the reference point towards the light
  float dist = 0;  // distance to the sampled point (infinity for the environment and directional lights)
  float pdf = 0;   // solid-angle density including the choice of light; for delta lights, the choice probability
  bool delta = false;
  Vec3 p_light;               // the sampled point (finite lights)
  Vec3 n_light;               // the surface normal there (area lights; zero for points)
  uint32_t light = kNoLight;  // which light (LightSet's index)
};

// A ray leaving a light, the start of a light path (Veach 1997, 10.2; pbrt-v4, 12.x "SampleLe"), with the densities
// of its origin and direction. Lights at infinity (environment, directional) emit from a disc as wide as the scene's
// bounding sphere, facing along the ray, placed outside the sphere.
struct LightEmission {
  // Emitted radiance along the ray; the intensity (W/sr) of point and spot lights, the irradiance (W/m^2) of a
  // directional light.
  Rgb radiance;
  Ray ray;            // unit direction
  Vec3 n;             // the emitting surface's normal (zero for point and spot lights; the ray's direction at infinity)
  float pdf_pos = 0;  // area density of the origin including the choice of light (a point light: the choice alone)
  float pdf_dir = 0;  // solid-angle density of the direction (a directional light: 1)
  uint32_t light = kNoLight;
  bool delta_pos = false;  // point and spot lights
  bool delta_dir = false;  // directional lights
  bool infinite = false;   // environment and directional lights
  // What emitted(w) reads: the radiance at the origin of an area light (emitted to the sides it emits to) or the
  // intensity of a point or spot light, whether an area light emits to the side of `n` alone, and the spot light.
  Rgb source;
  bool one_sided = false;
  const PunctualLight* spot = nullptr;
  // The radiance (an intensity for point and spot lights) the origin emits in another direction w: for connecting
  // the light's point to the camera. Not for lights at infinity.
  Rgb emitted(const Vec3& w) const;
  // What the emitted ray carries per unit of the two densities: radiance x |cos| at the origin / (pdf_pos pdf_dir),
  // the light path's initial throughput. Its mean over samples is the lights' total emitted power (per channel).
  Rgb weight() const {
    const float c = is_black(n) ? 1.0f : std::abs(dot(n, ray.dir));
    return radiance * (c / (pdf_pos * pdf_dir));
  }
};

class LightSet {
 public:
  // The lights of a scene: its emissive meshes and spheres (by their materials), its environment and its punctual
  // lights; the set keeps the addresses of the shapes, materials and environment (their owner, the scene, outlives
  // it and never moves them) and reads them when sampling.
  void build(const std::vector<Mesh>& meshes, const std::vector<Sphere>& spheres,
             const std::vector<std::unique_ptr<Material>>& materials, const Environment& environment,
             const Bounds& bounds, const std::vector<PunctualLight>& punctual);
  bool empty() const { return entries_.empty(); }
  size_t size() const { return entries_.size(); }

  // Samples one light as seen from `p`; false if nothing could be sampled.
  bool sample(const Vec3& p, float u_select, Vec2 u, LightSample* out) const;
  // Solid-angle density with which `sample` from `p` would have produced the emitting point of `si`.
  float pdf_hit(const Vec3& p, const SurfaceInteraction& si) const;
  // The probability of choosing the environment: times the environment's own density of a direction
  // (Environment::radiance(dir, &pdf)), the density with which `sample` produces that direction.
  float environment_pmf() const { return environment_ == kNoLight ? 0.0f : distribution_.pmf(environment_); }
  uint32_t environment_light() const { return environment_; }

  // Samples a ray leaving a light chosen in proportion to its power: u_select chooses the light, u_pos the origin,
  // u_dir the direction. False when nothing could be sampled.
  bool sample_emission(float u_select, Vec2 u_pos, Vec2 u_dir, LightEmission* out) const;
  // The densities sample_emission gives (choice of light included in pdf_pos) to a ray of direction `dir` leaving
  // light `light` at a point with surface normal `n` (area lights; ignored by the others). For the environment and
  // directional lights `dir` is the direction light travels.
  void emission_pdf(uint32_t light, const Vec3& n, const Vec3& dir, float* pdf_pos, float* pdf_dir) const;
  // Whether light `light` is a point or spot light (its position a delta) or a directional one (its direction).
  bool delta_position(uint32_t light) const;
  bool delta_direction(uint32_t light) const;

 private:
  enum class Kind : uint8_t { kTriangle, kSphere, kEnvironment, kPunctual };
  struct Entry {
    Kind kind;
    uint32_t object;  // mesh, sphere or punctual light index
    uint32_t prim;    // triangle index within its mesh
  };
  std::vector<Entry> entries_;
  // Per entry, for emissive triangles: the corner, edges, unit normal and area, so that sampling a triangle light
  // reads one compact record instead of the mesh's index and vertex arrays.
  struct TriangleGeometry {
    Vec3 p0, e1, e2, n;
    float area = 0;
    const Material* material = nullptr;  // the mesh's
  };
  std::vector<TriangleGeometry> triangles_;
  std::vector<PunctualLight> punctual_;
  const std::vector<Mesh>* meshes_ = nullptr;
  const std::vector<Sphere>* spheres_ = nullptr;
  const std::vector<std::unique_ptr<Material>>* materials_ = nullptr;
  const Environment* env_ = nullptr;
  Distribution1D distribution_;
  uint32_t environment_ = kNoLight;
  float scene_radius_ = 1;
  Vec3 scene_center_;
  // The origin and area density of a ray arriving from infinity along `dir` (the disc of the bounding sphere).
  Vec3 disc_origin(const Vec3& dir, Vec2 u) const;
  float disc_pdf() const { return 1 / (kPi * sqr(scene_radius_)); }
};

// The falloff of a spot light at cos_angle from its axis: glTF's KHR_lights_punctual smooth falloff (the square of
// the linear ramp) between the outer and inner cone, 1 inside, 0 outside.
float spot_falloff(const PunctualLight& light, float cos_angle);

}  // namespace tessera
