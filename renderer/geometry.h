// The shapes a scene is made of, in world or object space: triangle meshes (with the attributes shading reads),
// spheres, and instances of mesh groups; and their bounds. The acceleration structure (accel.h) and the scene
// (scene.h) both read them.
#pragma once

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "renderer/math.h"

namespace tessera {

struct Mesh {
  std::vector<Vec3> positions;
  std::vector<uint32_t> indices;     // 3 per triangle
  std::vector<Vec3> normals;         // per vertex, optional
  std::vector<Vec2> uvs;             // per vertex, optional
  std::vector<Vec2> uvs1;            // per vertex, optional second set
  std::vector<Rgb> colors;           // per vertex, optional
  std::vector<Vec3> tangents;        // per vertex, optional (with normals)
  std::vector<float> tangent_signs;  // per vertex bitangent sign, optional
  uint32_t material = 0;
  uint32_t first_light = 0;  // index of its first triangle's light when the material emits
  bool prototype = false;    // object-space geometry of a MeshGroup, traced only through its instances
  std::string name;          // the object's, for Cryptomatte (Scene::object_names)
  // Motion over a shutter (motion blur): the positions, and the normals when the mesh has them, at each of the
  // shutter's time steps, evenly spaced from its opening (ray time 0) to its closing (1), linear between them as
  // Embree interpolates them. Empty: the mesh stands still at `positions`, which hold its pose at the frame's time.
  std::vector<std::vector<Vec3>> motion_positions;
  std::vector<std::vector<Vec3>> motion_normals;
  size_t triangle_count() const { return indices.size() / 3; }
  bool moves() const { return motion_positions.size() >= 2; }
  // Vertex v's position and normal at ray time `time` in [0, 1] (the still ones when the mesh does not move).
  Vec3 position_at(uint32_t v, float time) const { return moves() ? at_time(motion_positions, v, time) : positions[v]; }
  Vec3 normal_at(uint32_t v, float time) const {
    return motion_normals.size() >= 2 ? at_time(motion_normals, v, time) : normals[v];
  }
  // Linear interpolation between the two time steps around `time`, as Embree's linear motion blur does (its time
  // steps at i / (n - 1)).
  static Vec3 at_time(const std::vector<std::vector<Vec3>>& steps, uint32_t v, float time) {
    const float f = std::clamp(time, 0.0f, 1.0f) * static_cast<float>(steps.size() - 1);
    const size_t i = std::min(static_cast<size_t>(f), steps.size() - 2);
    const float u = f - static_cast<float>(i);
    return steps[i][v] * (1 - u) + steps[i + 1][v] * u;
  }
};

// Meshes that several instances share (Embree instancing): traced once per instance through a transform.
// Emissive meshes are never instanced (lights are sampled in world space).
struct MeshGroup {
  std::vector<uint32_t> meshes;  // indices into Scene::meshes, each marked `prototype`
};

struct Instance {
  uint32_t group = 0;
  Transform to_world;
  Transform normal_to_world;  // inverse transpose of to_world's linear part
  bool mirrored = false;      // negative determinant: the front face is the clockwise one
  std::string name;           // the object's, for Cryptomatte (Scene::object_names)
};

struct Sphere {
  Vec3 center;
  float radius = 1;
  uint32_t material = 0;
  uint32_t light = 0;  // its light index when the material emits
  std::string name;    // the object's, for Cryptomatte (Scene::object_names)
};

// How far from the origin, in scene units, geometry may lie. Embree 3 aborts the process on a ray whose origin or
// direction has a component beyond 1.844e18 (FLT_LARGE in its RayK::valid assertion); 1e12 (a million kilometres in
// metres) leaves room for every distance a path computes from such coordinates, and a scene beyond it is a corrupt
// or mis-scaled asset, refused when it is loaded.
constexpr float kMaxSceneCoordinate = 1e12f;

struct Bounds {
  Vec3 lo{kInfinity, kInfinity, kInfinity};
  Vec3 hi{-kInfinity, -kInfinity, -kInfinity};
  void extend(const Vec3& p) {
    lo = vmin(lo, p);
    hi = vmax(hi, p);
  }
  bool empty() const { return lo.x > hi.x; }
  Vec3 center() const { return (lo + hi) * 0.5f; }
  float radius() const { return empty() ? 0 : 0.5f * length(hi - lo); }
};

}  // namespace tessera
