// The renderable scene: geometry, materials, lights, camera, environment, and the acceleration structure.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "renderer/accel.h"
#include "renderer/camera.h"
#include "renderer/environment.h"
#include "renderer/geometry.h"
#include "renderer/interaction.h"
#include "renderer/lights.h"
#include "renderer/material/material.h"

namespace tessera {

class Scene {
 public:
  std::vector<std::unique_ptr<Material>> materials;
  std::vector<std::string> material_names;
  std::vector<Mesh> meshes;
  std::vector<Sphere> spheres;
  std::vector<MeshGroup> groups;
  std::vector<Instance> instances;
  CameraDesc camera;
  // An animated camera's poses at a shutter's time steps, evenly spaced from its opening (ray time 0) to its closing
  // (1); empty: the camera stands still at `camera` (camera_at, camera.h).
  std::vector<CameraDesc> camera_motion;
  Environment environment;
  // The medium around the objects, where the camera and the lights sit (null: vacuum); objects' media are their
  // materials' interiors (Material::interior).
  std::shared_ptr<const Medium> medium;
  std::vector<std::string> warnings;  // things the user should fix or know were ignored
  std::vector<std::string> notes;     // defaults that were applied

  // Builds lights and the acceleration structure; call once after filling the fields above.
  void finalize();
  void finalize_with_lights(const std::vector<PunctualLight>& punctual);

  // `cone`, when given, sets the hit's uv footprint (ShadingPoint::uv_footprint) for texture filtering.
  bool intersect(const Ray& ray, SurfaceInteraction* si, const RayCone* cone = nullptr) const;
  // The surface point of a hit `ray` found (by intersect() or in a packet with Accel::intersect_packet).
  void interaction(const Ray& ray, const RayHit& hit, SurfaceInteraction* si, const RayCone* cone = nullptr) const;
  bool occluded(const Ray& ray) const { return accel_.occluded(ray); }
  // The bare ray queries, without shading (for measuring what Embree alone costs).
  const Accel& accel() const { return accel_; }
  const LightSet& lights() const { return lights_; }
  const Bounds& bounds() const { return bounds_; }
  // The world-space bounds of every shape (instanced meshes through their transforms), worked out afresh from the
  // fields above; *finite (when given) is false when a vertex, a sphere or an instance's placement is not a finite
  // number.
  Bounds geometry_bounds(bool* finite = nullptr) const;
  // The names of the objects, by number (SurfaceInteraction::object: meshes, then spheres, then instances); an
  // object without a name of its own is called by its number, "object 7".
  std::vector<std::string> object_names() const;
  size_t triangle_count() const;         // triangles traced, instances counted each time
  size_t unique_triangle_count() const;  // triangles stored
  double build_seconds() const { return build_seconds_; }
  // Whether any material disperses (Material::dispersive): only then do paths carry a wavelength.
  bool dispersive() const { return dispersive_; }
  // Whether some medium scatters light (Medium::scatters), worked out afresh from the fields above (a scene that
  // was not finalized may ask); scattering() is the same, as finalize found it.
  bool has_scattering_media() const;
  bool scattering() const { return scattering_; }
  // Whether some material is an index-matched boundary (Material::index_matched): only then may shadow rays cross
  // surfaces.
  bool index_matched() const { return index_matched_; }
  // Whether anything moves over the shutter (a mesh's motion_positions, camera_motion): only then do the camera's
  // samples draw a time (motion blur), as finalize found it.
  bool moving() const { return moving_; }

 private:
  Accel accel_;
  LightSet lights_;
  Bounds bounds_;
  double build_seconds_ = 0;
  bool dispersive_ = false;
  bool scattering_ = false;
  bool index_matched_ = false;
  bool moving_ = false;
};

// Keeps the first of each warning given more than once, in order, and at most kMaxWarnings of them: the rest are
// counted in a last line ("and 9,990 more warnings"). An asset may make any number (one per unknown extension or
// per material), and every warning is stored with the job and written to its log.
constexpr size_t kMaxWarnings = 32;
void tidy_warnings(std::vector<std::string>* warnings);

// Bends the shading frame of `sp` by the material's normal map, seen from direction `wo` (world, towards where the
// ray came from; any length), and keeps the mirror reflection of wo above the surface
// (keep_reflection_above_surface).
void apply_normal_map(const Material& material, const Vec3& wo, ShadingPoint* sp);
// The normal `map` (tangent space, x and y scaled by `scale`) gives at `sp`, in world space, from sp's frame; zero
// where the map's normal is unusable or points under the surface.
Vec3 mapped_normal(const Texture& map, float scale, const ShadingPoint& sp);

// A shading normal bent so that the mirror reflection of `wo` about it stays above the geometric surface (normal
// `ng`), on wo's side: where a normal map tilts the normal so far that the reflection would point into the surface,
// the reflection is raised to just above the horizon and the normal becomes the half vector of wo and that
// reflection. Otherwise paths die there and strong normal maps on metals show black crescents. This is the shading
// normal adaption of Keller et al. 2017, "The Iray Light Transport Simulation and Rendering System" (also Blender
// Cycles' ensure_valid_reflection); `n` is returned unchanged where its reflection is valid.
Vec3 keep_reflection_above_surface(const Vec3& n, const Vec3& ng, const Vec3& wo);

// Offsets a ray origin off the surface at `p` along the geometric normal towards `dir`, against self-intersection.
Vec3 offset_ray_origin(const Vec3& p, const Vec3& ng, const Vec3& dir);

}  // namespace tessera
