// Integrators: the algorithms that estimate each pixel's measurement (the measurement equation of Dutré, Bala &
// Bekaert, Advanced Global Illumination, 2nd ed., §2.8) from the scene. An integrator renders one pass at a time, a
// range of sample indices for every pixel of the render's region, into a film, on the render's thread pool; a registry
// creates them by name, as the material registry does models:
//   path   unidirectional path tracing from the camera (Kajiya 1986; Dutré et al., §2.6), with a choice of estimator
//   light  light tracing: paths from the lights joined to the lens and splatted where they land (Veach 1997, 10.2)
//   bdpt   bidirectional path tracing: subpaths from both ends joined in every way, weighted by the power heuristic
//          (Veach 1997, ch. 10)
// Every integrator keeps the image a function of (seed, pixel, sample index) alone, whatever the threads or passes.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "renderer/arena.h"
#include "renderer/camera.h"
#include "renderer/film.h"
#include "renderer/medium.h"
#include "renderer/sampler.h"

namespace tessera {

namespace cryptomatte {
struct Ids;
}  // namespace cryptomatte

class Bsdf;
class Scene;
class ThreadPool;
struct LightSample;
struct ShadingPoint;
struct SurfaceFeatures;

// How the path tracer estimates direct light at each path vertex.
enum class Estimator {
  kHemisphere,  // BSDF sampling only: the hemisphere form (Dutré et al., §4.1.1); light is found by hitting emitters
  kArea,        // light sampling only: the area form (Dutré et al., §4.1.2), next-event estimation towards lights
  kMis,         // both, weighted by the power heuristic (Veach 1997)
};
// Documents name them: estimator_name (render_settings.h).

struct IntegratorSettings {
  std::string name = "path";              // the integrator, by its registry name
  Estimator estimator = Estimator::kMis;  // the path tracer's
  int max_depth = 8;                      // maximum number of surface scattering events along a path
  // Maximum number of scattering events in media and crossings of index-matched boundaries along a path (they do not
  // count towards max_depth; Blender Cycles keeps the same separate limit for volume bounces).
  int max_volume_depth = 256;
  // Whether walks in subsurface media are guided towards the surface they last met (integrators/guided_walk.h).
  bool subsurface_guiding = true;
  int rr_start_depth = 3;  // Russian roulette from this many bounces on
  bool operator==(const IntegratorSettings&) const = default;
};

// Counts of rays traced, by kind, per thread; summed by the session.
struct RayCounters {
  uint64_t camera = 0;
  uint64_t bounce = 0;
  uint64_t shadow = 0;
  RayCounters& operator+=(const RayCounters& o) {
    camera += o.camera;
    bounce += o.bounce;
    shadow += o.shadow;
    return *this;
  }
  uint64_t total() const { return camera + bounce + shadow; }
};

// Which pixels of an image sample in a pass: 1 for those that do, one byte per pixel, row-major from the top left.
using PixelMask = std::vector<uint8_t>;

// A rectangle of pixels: (x, y) its top-left pixel.
struct PixelRegion {
  int x = 0, y = 0, width = 0, height = 0;
  bool operator==(const PixelRegion&) const = default;
};

// The region cut into square tiles (the last row and column may be smaller): the thread pool's work items.
struct TileGrid {
  TileGrid() = default;
  TileGrid(const PixelRegion& region, int tile_size);
  size_t count() const { return static_cast<size_t>(tiles_x) * static_cast<size_t>(tiles_y); }
  PixelRegion tile(size_t index) const;
  PixelRegion region;
  int tile_size = 32;
  int tiles_x = 0, tiles_y = 0;
};

// What an integrator renders: the scene through the camera at a resolution, the pixels of a region of it, with the
// render's seed and sample sequence, on a thread pool.
struct IntegratorSetup {
  std::shared_ptr<const Scene> scene;
  Camera camera;
  int width = 0, height = 0;
  PixelRegion region;  // within the image
  uint64_t seed = 0;
  SamplerKind sampler = SamplerKind::kSobol;
  IntegratorSettings settings;
  uint32_t samples_per_pixel = 1;  // the whole job's, for the rays' cones (Camera::pixel_cone)
  int tile_size = 32;
  ThreadPool* pool = nullptr;
  // The scene's Cryptomatte ids, for a film with Cryptomatte passes (aov.h); null otherwise.
  std::shared_ptr<const cryptomatte::Ids> crypto;
};

// The shadow ray from a surface point (p, geometric normal ng) to a sampled light point: both ends offset clear of
// self-intersection, the direction unnormalised so that t = 1 is the light's point; to infinity for a light at
// infinity (ls.dist infinite).
Ray shadow_ray_to_light(const Vec3& p, const Vec3& ng, const LightSample& ls, float time);

// The fraction of radiance that travels along `shadow` (to its tmax) through the media from `medium` on: zero when a
// surface blocks it, else the media's transmittance (estimated with `rng` in media from grids). Index-matched
// boundaries (Material::index_matched) do not block: the shadow ray crosses them and changes medium as a path does, up
// to `max_crossings` of them. Every integrator's shadow rays and connections go through it.
Rgb shadow_transmittance(const Scene& scene, Ray shadow, MediumTracker medium, int max_crossings, MediumRng& rng,
                         RayCounters& counters);

// The seed of a path's MediumRng: a hash of a ray that the pixel sample's numbers jitter (its camera ray), so that
// each sample's stream differs and a render is repeatable, without drawing a sampler dimension (the layout of every
// other number, and so every render without heterogeneous media, stays as it was).
uint64_t ray_seed(const Ray& ray);

// A camera sample's time within the shutter and the camera at it (motion blur): in a scene that moves
// (Scene::moving), the time is the sampler's reserved time dimension (PixelSampler::get1d_time) and a moving camera is
// posed at it (camera_at); elsewhere the time is 0 and the camera the setup's, and the sampler is not read.
struct CameraAtTime {
  float time = 0;
  Camera posed;                    // the moving camera at `time`
  const Camera* camera = nullptr;  // `posed` or the setup's
};
void camera_at_time(const IntegratorSetup& setup, const PixelSampler& sampler, CameraAtTime* out);

// The render passes' records of a camera sample (SurfaceFeatures, aov.h), written the same way by every integrator
// that traces from the camera. note_surface: the camera ray's first drawn surface (at `sp`, of the object and material
// SurfaceInteraction numbers), `distance` along the camera ray from the lens, with its BSDF (null for a surface that
// does not scatter). note_shading: the first surface whose BSDF is not wholly a delta lobe (albedo times the
// `throughput` of the delta bounces before it, shading normal `n` turned to face `wo`, the direction back along the
// path); a null `bsdf` with a zero `n` stands for a scattering event in a medium, whose albedo is the throughput alone.
void note_surface(SurfaceFeatures& f, const ShadingPoint& sp, uint32_t object, uint32_t material_index,
                  const Bsdf* bsdf, float distance);
void note_shading(SurfaceFeatures& f, const Rgb& throughput, const Bsdf* bsdf, const Vec3& n, const Vec3& wo);

class Integrator {
 public:
  explicit Integrator(IntegratorSetup setup);
  virtual ~Integrator() = default;
  Integrator(const Integrator&) = delete;
  Integrator& operator=(const Integrator&) = delete;

  // Adds sample indices [first_sample, first_sample + count) of every pixel of the region to `film`, without
  // changing its sample count; with `active`, of the pixels of the region it marks alone (adaptive sampling,
  // adaptive.h): an integrator that cannot sample pixels apart (integrator_adaptive_problem) throws
  // std::invalid_argument. Returns early, the film incomplete, once `cancel` is set.
  virtual void render_pass(uint32_t first_sample, uint32_t count, Film& film, const std::atomic<bool>& cancel,
                           const PixelMask* active = nullptr) = 0;

  // Whether the film's squared-luminance sums measure the image's noise (Film::relative_error): not when every
  // sample is a splat that lands in some other pixel (light tracing).
  virtual bool measures_noise() const { return true; }

  // Totals since the integrator was made: rays traced, and samples dropped for being infinite, NaN or negative.
  RayCounters rays() const;
  uint64_t nonfinite_samples() const;

 protected:
  // Scratch state of one pool worker: its arena, and its counters, added to once per work item (the slots of
  // different workers share cache lines, and adding per ray would make the threads fight over them).
  struct Worker {
    ScratchArena arena;
    RayCounters rays;
    uint64_t nonfinite = 0;
  };
  Worker& worker(int index) { return *workers_[static_cast<size_t>(index)]; }

  IntegratorSetup setup_;
  TileGrid tiles_;

 private:
  std::vector<std::unique_ptr<Worker>> workers_;  // one per pool worker
};

// Makes an integrator for `setup`; throws std::invalid_argument when it cannot render it.
using IntegratorFactory = std::function<std::unique_ptr<Integrator>(const IntegratorSetup& setup)>;

class IntegratorRegistry {
 public:
  // The registry with every built-in integrator.
  static const IntegratorRegistry& builtin();

  void add(const std::string& name, IntegratorFactory factory);
  bool has(const std::string& name) const { return factories_.count(name) != 0; }
  std::vector<std::string> names() const;
  // The integrator setup.settings.name names; throws std::invalid_argument for a name it does not have.
  std::unique_ptr<Integrator> create(const IntegratorSetup& setup) const;

 private:
  std::map<std::string, IntegratorFactory> factories_;
};

// What keeps the integrator `name` from rendering through `camera`, or empty: light tracing and BDPT join paths to
// the lens through the camera's importance, which only a perspective camera has.
std::string integrator_camera_problem(const std::string& name, const Camera& camera);

// What keeps the integrator `name` from making the render pass `aov` (aov.h), or empty: light tracing splats every
// sample where it lands, so it has no first surface per pixel nor a pixel's own samples for a variance; BDPT's pixels
// take splats from other pixels' light subpaths, so their samples do not give their variance either.
std::string integrator_aov_problem(const std::string& name, std::string_view aov);

// What keeps the integrator `name` from sampling pixels adaptively (render.adaptive_threshold), or empty: light
// tracing and BDPT splat light paths onto every pixel, so a pixel's own samples do not measure its error, and their
// light paths cannot be kept from the pixels that stopped.
std::string integrator_adaptive_problem(const std::string& name);

// What one pixel sample of the integrator `settings` names may cost, counted in path events for a job's work limit:
// max_depth bounces off surfaces, and in a scene whose media scatter (`scattering`) up to max_volume_depth events in
// media besides; BDPT joins every vertex of its camera subpath to every vertex of its light subpath, so its count is
// those events squared. `formula` receives how it was counted ("(max_depth + max_volume_depth)^2"), for a refusal.
double sample_work(const IntegratorSettings& settings, bool scattering, std::string* formula);

// Adds every integrator the renderer ships to `registry` (one line per integrator in integrators/registry.cpp).
void register_builtin_integrators(IntegratorRegistry& registry);

}  // namespace tessera
