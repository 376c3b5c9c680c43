// Light sampling for next-event estimation (seed 000, 2.6: the area form of the rendering equation, and the direct
// illumination it isolates): emissive triangles and spheres, point and directional lights, and the environment,
// chosen in proportion to their emitted power.
#pragma once

#include <cstdint>
#include <vector>

#include "renderer/math.h"
#include "renderer/sampling.h"

namespace tessera {

class Material;
class Scene;
struct SurfaceInteraction;

inline constexpr uint32_t kNoLight = ~0u;

struct PunctualLight {
  enum class Kind { kPoint, kSpot, kDirectional };
  Kind kind = Kind::kPoint;
  Vec3 position;
  Vec3 direction{0, -1, 0};  // direction the light travels (spot and directional)
  Rgb intensity{1, 1, 1};     // W/sr per channel for point and spot (candela in glTF), W/m^2 for directional (lux)
  float cos_inner = 1, cos_outer = 0;  // spot cone
};

struct LightSample {
  Rgb radiance;   // arriving at the reference point along -wi (for delta lights: intensity / dist^2 or irradiance)
  Vec3 wi;        // unit direction from the reference point towards the light
  float dist = 0; // distance to the sampled point (infinity for the environment and directional lights)
  float pdf = 0;  // solid-angle density including the choice of light; for delta lights, the choice probability
  bool delta = false;
  Vec3 p_light;   // the sampled point (finite lights)
  Vec3 n_light;   // the surface normal there (area lights; zero for points)
};

class LightSet {
 public:
  void build(const Scene& scene, const std::vector<PunctualLight>& punctual);
  bool empty() const { return entries_.empty(); }
  size_t size() const { return entries_.size(); }

  // Samples one light as seen from `p`; false if nothing could be sampled.
  bool sample(const Scene& scene, const Vec3& p, float u_select, Vec2 u, LightSample* out) const;
  // Solid-angle density with which `sample` from `p` would have produced the emitting point of `si`.
  float pdf_hit(const Scene& scene, const Vec3& p, const SurfaceInteraction& si) const;
  // The probability of choosing the environment: times the environment's own density of a direction
  // (Environment::radiance(dir, &pdf)), the density with which `sample` produces that direction.
  float environment_pmf() const { return environment_ == kNoLight ? 0.0f : distribution_.pmf(environment_); }

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
  Distribution1D distribution_;
  uint32_t environment_ = kNoLight;
  float scene_radius_ = 1;
};

}  // namespace tessera
