// Ray queries. This module owns every Embree call; nothing else includes Embree headers.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "renderer/math.h"

namespace tessera {

struct Mesh;
struct Sphere;
struct MeshGroup;
class Material;
struct Instance;
inline constexpr uint32_t kNoInstance = ~0u;

struct RayHit {
  float t = kInfinity;
  float u = 0, v = 0;  // barycentrics of vertices 1 and 2 (triangles)
  Vec3 ng;             // unnormalised geometric normal, world
  uint32_t geom_id = 0;
  uint32_t prim_id = 0;
  bool is_sphere = false;
  uint32_t object = 0;              // index into Scene::meshes or Scene::spheres
  uint32_t instance = kNoInstance;  // index into Scene::instances for instanced geometry
};

class Accel {
 public:
  Accel();
  ~Accel();
  Accel(const Accel&) = delete;
  Accel& operator=(const Accel&) = delete;

  // `materials` by material index: masked and blended ones get a coverage filter.
  void build(const std::vector<Mesh>& meshes, const std::vector<Sphere>& spheres, const std::vector<MeshGroup>& groups,
             const std::vector<Instance>& instances, const std::vector<const Material*>& materials);
  bool intersect(const Ray& ray, RayHit* hit) const;
  bool occluded(const Ray& ray) const;
  // Closest hits of up to kPacketSize rays traced together as one Embree packet: faster than one by one for
  // coherent rays (camera rays through neighbouring pixels). found[i] says whether rays[i] hit; each hit is the one
  // intersect() would report (Embree's packet kernels may round a sphere hit's t and normal differently).
  static constexpr int kPacketSize = 8;
  void intersect_packet(const Ray* rays, int count, RayHit* hits, bool* found) const;

 private:
  bool resolve(float t, float u, float v, Vec3 ng, uint32_t geom_id, uint32_t prim_id, uint32_t inst_id,
               RayHit* hit) const;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
