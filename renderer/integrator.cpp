#include "renderer/integrator.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <stdexcept>

#include "renderer/aov.h"
#include "renderer/lights.h"
#include "renderer/scene.h"
#include "renderer/thread_pool.h"

namespace tessera {

void camera_at_time(const IntegratorSetup& setup, const PixelSampler& sampler, CameraAtTime* out) {
  const Scene& scene = *setup.scene;
  out->camera = &setup.camera;
  out->time = 0;
  if (!scene.moving()) return;
  out->time = sampler.get1d_time();
  if (scene.camera_motion.empty()) return;
  out->posed = Camera(camera_at(scene.camera_motion, out->time), setup.width, setup.height);
  out->camera = &out->posed;
}

Ray shadow_ray_to_light(const Vec3& p, const Vec3& ng, const LightSample& ls, float time) {
  Ray shadow;
  shadow.time = time;
  shadow.origin = offset_ray_origin(p, ng, ls.wi);
  if (std::isinf(ls.dist)) {
    shadow.dir = ls.wi;
    shadow.tmax = kInfinity;
  } else {
    const Vec3 target = is_black(ls.n_light) ? ls.p_light : offset_ray_origin(ls.p_light, ls.n_light, -ls.wi);
    shadow.dir = target - shadow.origin;
    shadow.tmax = 1 - 1e-5f;
  }
  return shadow;
}

Rgb shadow_transmittance(const Scene& scene, Ray shadow, MediumTracker medium, int max_crossings, MediumRng& rng,
                         RayCounters& counters) {
  ++counters.shadow;
  Rgb tr(1);
  if (!scene.index_matched()) {
    if (scene.occluded(shadow)) return Rgb(0);
    medium.attenuate(tr, shadow, shadow.tmax, rng);
    return tr;
  }
  for (int crossings = 0;; ++crossings) {
    SurfaceInteraction si;
    if (!scene.intersect(shadow, &si)) {
      medium.attenuate(tr, shadow, shadow.tmax, rng);
      return tr;
    }
    if (!si.material->index_matched() || crossings >= max_crossings) return Rgb(0);
    medium.attenuate(tr, shadow, si.t, rng);
    medium.refract(si.sp.front_face, si.material->interior());
    shadow.origin = offset_ray_origin(si.sp.p, si.sp.ng, shadow.dir);
    shadow.tmax -= si.t;
    ++counters.shadow;
  }
}

uint64_t ray_seed(const Ray& ray) {
  uint64_t h = 0;
  for (float f : {ray.origin.x, ray.origin.y, ray.origin.z, ray.dir.x, ray.dir.y, ray.dir.z})
    h = mix64(h ^ std::bit_cast<uint32_t>(f));
  return h;
}

void note_surface(SurfaceFeatures& f, const ShadingPoint& sp, uint32_t object, uint32_t material_index,
                  const Bsdf* bsdf, float distance) {
  f.surface = true;
  f.depth = distance;
  f.position = sp.p;
  f.uv = sp.uv;
  f.roughness = bsdf ? bsdf->roughness_hint() : 1.0f;
  f.object = object;
  f.material = material_index;
}

void note_shading(SurfaceFeatures& f, const Rgb& throughput, const Bsdf* bsdf, const Vec3& n, const Vec3& wo) {
  f.shaded = true;
  f.albedo = bsdf ? throughput * bsdf->albedo_hint() : (is_black(n) ? throughput : Rgb(0));
  f.normal = dot(n, wo) < 0 ? -n : n;
}

TileGrid::TileGrid(const PixelRegion& r, int size) : region(r), tile_size(size) {
  tiles_x = (region.width + tile_size - 1) / tile_size;
  tiles_y = (region.height + tile_size - 1) / tile_size;
}

PixelRegion TileGrid::tile(size_t index) const {
  const int tx = static_cast<int>(index % static_cast<size_t>(tiles_x));
  const int ty = static_cast<int>(index / static_cast<size_t>(tiles_x));
  PixelRegion t;
  t.x = region.x + tx * tile_size;
  t.y = region.y + ty * tile_size;
  t.width = std::min(t.x + tile_size, region.x + region.width) - t.x;
  t.height = std::min(t.y + tile_size, region.y + region.height) - t.y;
  return t;
}

Integrator::Integrator(IntegratorSetup setup) : setup_(std::move(setup)), tiles_(setup_.region, setup_.tile_size) {
  for (int i = 0; i < setup_.pool->size(); ++i) workers_.push_back(std::make_unique<Worker>());
}

RayCounters Integrator::rays() const {
  RayCounters total;
  for (const auto& w : workers_) total += w->rays;
  return total;
}

uint64_t Integrator::nonfinite_samples() const {
  uint64_t total = 0;
  for (const auto& w : workers_) total += w->nonfinite;
  return total;
}

const IntegratorRegistry& IntegratorRegistry::builtin() {
  static const IntegratorRegistry registry = [] {
    IntegratorRegistry r;
    register_builtin_integrators(r);
    return r;
  }();
  return registry;
}

void IntegratorRegistry::add(const std::string& name, IntegratorFactory factory) {
  factories_[name] = std::move(factory);
}

std::vector<std::string> IntegratorRegistry::names() const {
  std::vector<std::string> out;
  for (const auto& [name, factory] : factories_) out.push_back(name);
  return out;
}

std::unique_ptr<Integrator> IntegratorRegistry::create(const IntegratorSetup& setup) const {
  auto it = factories_.find(setup.settings.name);
  if (it == factories_.end()) throw std::invalid_argument("no integrator named \"" + setup.settings.name + "\"");
  return it->second(setup);
}

}  // namespace tessera
