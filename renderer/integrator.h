// Unbiased path tracing of the rendering equation (seed 000, 2.6; seed 003, Monte Carlo path tracing).
#pragma once

#include <cstdint>
#include <string>

#include "renderer/accel.h"
#include "renderer/arena.h"
#include "renderer/math.h"
#include "renderer/sampler.h"

namespace tessera {

class Scene;

// How direct light is estimated at each path vertex.
enum class Estimator {
  kHemisphere,  // BSDF sampling only: the hemisphere form (seed 003, 4.1.1); light is found by hitting emitters
  kArea,        // light sampling only: the area form (seed 003, 4.1.2), next-event estimation towards lights
  kMis,         // both, weighted by the power heuristic (Veach 1997)
};

const char* estimator_name(Estimator e);
bool parse_estimator(const std::string& name, Estimator* out);

struct IntegratorSettings {
  Estimator estimator = Estimator::kMis;
  int max_depth = 8;          // maximum number of scattering events along a path
  int rr_start_depth = 3;     // Russian roulette from this many bounces on
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

// The camera ray's closest hit when the caller has traced it already (camera rays of neighbouring pixels go to
// Embree together, as a packet).
struct PrimaryHit {
  bool found = false;
  RayHit hit;
};

// Radiance arriving at the camera along `ray`. With `primary`, the camera ray's hit is taken from it rather than
// traced again. `cone` is the camera ray's (Camera::pixel_cone); each bounce carries it on, widened by how much the
// sampled lobe spreads, and textures are filtered over its footprint. A zero cone reads the finest texels.
Rgb trace_path(const Scene& scene, const Ray& ray, const PrimaryHit* primary, PixelSampler& sampler,
               const IntegratorSettings& settings, ScratchArena& arena, RayCounters& counters,
               RayCone cone = RayCone());

}  // namespace tessera
