// The path tracer (`path`): unbiased path tracing of the rendering equation from the camera (Kajiya 1986, "The
// Rendering Equation"; Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed., §2.6 and ch. 5), with direct light
// estimated by BSDF sampling, light sampling, or both weighted by multiple importance sampling (Veach 1997, ch. 9), and
// Russian roulette. In participating media the path samples free flights and scatters by the phase function, with
// next-event estimation through the media to the lights (the volumetric path tracer of Pharr, Jakob and Humphreys,
// Physically Based Rendering, 4th ed., §14.2: the transmittance of homogeneous media in closed form, that of media
// from grids by ratio tracking and their free flights by delta tracking, grid_medium.h).
#include "renderer/aov.h"
#include "renderer/integrator.h"
#include "renderer/integrators/guided_walk.h"
#include "renderer/phase.h"
#include "renderer/scene.h"
#include "renderer/spectrum.h"
#include "renderer/thread_pool.h"

namespace tessera {

namespace {

// How a light sample's contribution splits between the lobe classes (Bsdf::eval_diffuse), for the light passes.
struct LightSplit {
  Rgb diffuse;             // the diffuse lobes' part
  bool transmits = false;  // the rest is transmission (the light is beyond the surface), else glossy
};

// Next-event estimation at a path vertex: one light sample's contribution, before the path's throughput, weighed
// against BSDF sampling by the power heuristic with `mis`. `medium` is the medium the path arrived in. `split`, when
// given, receives how the contribution splits between the lobe classes.
Rgb direct_light(const Scene& scene, const SurfaceInteraction& si, const Bsdf& bsdf, uint32_t flags,
                 const Vec3& wo_world, const Vec3& wo, bool mis, float u_select, Vec2 u, const MediumTracker& medium,
                 float time, int max_crossings, MediumRng& rng, RayCounters& counters, LightSplit* split = nullptr) {
  LightSample ls;
  if (!scene.lights().sample(si.sp.p, u_select, u, &ls) || !(ls.pdf > 0) || is_black(ls.radiance)) return {};
  const Vec3 wi = si.sp.frame.to_local(ls.wi);
  // Which side of the geometric surface the light is on decides reflection or transmission, whatever the shading
  // normal says (otherwise light leaks through surfaces with interpolated normals).
  const bool light_transmits = dot(ls.wi, si.sp.ng) * dot(wo_world, si.sp.ng) <= 0;
  if (!(flags & (light_transmits ? kBsdfTransmission : kBsdfReflection))) return {};
  // The BSDF's pdf is needed only to weight a non-delta light sample by MIS; eval_pdf shares the work.
  const bool weigh = mis && !ls.delta;
  float bsdf_pdf = 0;
  const Rgb f = (weigh ? bsdf.eval_pdf(wo, wi, &bsdf_pdf) : bsdf.eval(wo, wi)) * std::abs(wi.z);
  if (is_black(f)) return {};
  const Ray shadow = shadow_ray_to_light(si.sp.p, si.sp.ng, ls, time);
  // The shadow ray starts in the medium on the light's side of the surface.
  MediumTracker beyond = medium;
  if (light_transmits) beyond.refract(si.sp.front_face, si.material->interior());
  const Rgb tr = shadow_transmittance(scene, shadow, beyond, max_crossings, rng, counters);
  if (is_black(tr)) return {};
  const float w = weigh ? power_heuristic(ls.pdf, bsdf_pdf) : 1.0f;
  if (split) {
    split->diffuse = bsdf.eval_diffuse(wo, wi) * std::abs(wi.z) * ls.radiance * (w / ls.pdf) * tr;
    split->transmits = light_transmits;
  }
  return f * ls.radiance * (w / ls.pdf) * tr;
}

// After a surface event from which the path goes on along `dir`: in a subsurface medium, the walk is guided towards
// that surface, whose outward normal is the side of `ng` that `dir` leaves; elsewhere, no walk is guided.
void note_walk_surface(const MediumTracker& medium, const Vec3& ng, const Vec3& dir, std::optional<Vec3>& walk_normal) {
  if (medium.current() && medium.current()->subsurface()) {
    const Vec3 n = normalize(ng);
    walk_normal = dot(dir, n) < 0 ? n : -n;
  } else {
    walk_normal.reset();
  }
}

// Next-event estimation at a scattering event in a medium, at `p`: the phase function takes the BSDF's place.
Rgb direct_light_in_medium(const Scene& scene, const Vec3& p, const Vec3& wo_world, const HenyeyGreenstein& phase,
                           bool mis, float u_select, Vec2 u, const MediumTracker& medium, float time, int max_crossings,
                           MediumRng& rng, RayCounters& counters) {
  LightSample ls;
  if (!scene.lights().sample(p, u_select, u, &ls) || !(ls.pdf > 0) || is_black(ls.radiance)) return {};
  const float f = phase.p(wo_world, ls.wi);
  if (!(f > 0)) return {};
  // A point in a medium has no surface to leave: the shadow ray starts at it.
  const Ray shadow = shadow_ray_to_light(p, Vec3(0), ls, time);
  const Rgb tr = shadow_transmittance(scene, shadow, medium, max_crossings, rng, counters);
  if (is_black(tr)) return {};
  const float w = mis && !ls.delta ? power_heuristic(ls.pdf, f) : 1.0f;
  return ls.radiance * tr * (f * w / ls.pdf);
}

// The camera ray's closest hit when the caller has traced it already (camera rays of neighbouring pixels go to
// Embree together, as a packet).
struct PrimaryHit {
  bool found = false;
  RayHit hit;
};

// A vertex's light-sample numbers (one to choose the light, two for the point on it), in the fixed layout every
// vertex has, surface or medium: spent whether or not the light is sampled, so that the numbers the rest of the path
// draws do not depend on it.
struct LightNumbers {
  float select = 0;
  Vec2 u{};
};
LightNumbers light_numbers(PixelSampler& sampler, bool sample_light) {
  LightNumbers n;
  if (sample_light) {
    n.select = sampler.get1d();
    n.u = sampler.get2d();
  } else {
    sampler.skip1d();
    sampler.skip2d();
  }
  return n;
}

// Radiance arriving at the camera along `ray`. With `primary`, the camera ray's hit is taken from it rather than
// traced again. `cone` is the camera ray's (Camera::pixel_cone); each bounce carries it on, widened by how much the
// sampled lobe spreads, and textures are filtered over its footprint. A zero cone reads the finest texels.
// `wavelength`, in a scene with dispersive materials, is the pixel sample's (spectrum.h): every BSDF sees it, and the
// throughput takes its weight at the path's first dispersive vertex, before anything is added through that vertex.
// `features`, when given, receives what the render passes record of the path (note_surface, note_shading), and `light`
// the light passes' split of its radiance (aov.h).
Rgb trace_path(const Scene& scene, const Ray& camera_ray, const PrimaryHit* primary, PixelSampler& sampler,
               const IntegratorSettings& settings, ScratchArena& arena, RayCounters& counters, RayCone cone,
               const spectrum::WavelengthSample* wavelength, SurfaceFeatures* features, LightPassSample* light) {
  const LightSet& lights = scene.lights();
  const bool use_light_sampling = settings.estimator != Estimator::kHemisphere;
  const bool use_bsdf_hits = settings.estimator != Estimator::kArea;
  const bool mis = settings.estimator == Estimator::kMis;

  Rgb radiance(0);
  Rgb throughput(1);
  Ray ray = camera_ray;
  // State of the previous scattering event, for weighting emission found by BSDF sampling.
  bool prev_delta = true;  // the camera ray counts as a delta event: emitters it sees are added fully
  float prev_pdf = 0;
  Vec3 prev_p;
  float eta_scale = 1;                         // product of eta^2 across refractions, kept out of Russian roulette
  MediumTracker medium(scene.medium.get());    // the medium the path is travelling through
  MediumRng medium_rng(ray_seed(camera_ray));  // the further numbers of heterogeneous media (medium.h)
  bool dispersed = false;                      // the throughput carries the wavelength's weight
  const bool scattering = scene.scattering();  // whether any medium scatters: only then are free flights sampled
  // Scattering events in media and crossings of index-matched boundaries: they are not bounces (depth), and have
  // their own limit, settings.max_volume_depth.
  int volume_depth = 0;
  // A subsurface walk's guiding (guided_walk.h): the outward normal of the surface it last met, and the step whose
  // direction a scattering event sampled, which draws the distance of the flight after it.
  const bool guiding = settings.subsurface_guiding;
  std::optional<Vec3> walk_normal;
  std::optional<GuidedWalk> walk;  // the constants of the medium walked in last
  std::optional<GuidedWalkStep> guided;
  bool camera_segment = true;  // the ray is the camera ray, whose hit `primary` may hold
  // For `features`: whether the path still runs along the camera ray (only index-matched boundaries crossed), and
  // how far it has come along it.
  bool straight = true;
  float travelled = 0;
  // For `light`: the scattering events (surface bounces, medium scatterings) before the current ray, and the class of
  // the first (Bsdf's lobe classes 0 diffuse, 1 glossy, 2 transmission; 3 a medium). Light that reached the camera
  // after k of them is emission or background for k = 0, the first class's direct for k = 1, its indirect after.
  int bounces = 0, first = -1;
  auto record = [&](const Rgb& c, int k, bool background) {
    if (!light) return;
    if (k == 0)
      (background ? light->background : light->emission) += c;
    else if (first == 3)
      (k == 1 ? light->volume_direct : light->volume_indirect) += c;
    else if (first >= 0)
      (k == 1 ? light->direct[first] : light->indirect[first]) += c;
  };
  ++counters.camera;

  for (int depth = 0;;) {
    arena.reset();
    SurfaceInteraction si;
    bool found;
    // In a scattering medium the path may interact before the surface (or infinity): free-flight sampling decides
    // (medium.h), and a scattering event is a path vertex whose phase function is sampled, and light sampled, as a
    // BSDF's is at a surface. Its numbers follow the free flight's in the same layout as a surface vertex's.
    const Medium* current = medium.current();
    const bool in_scattering_medium = scattering && current && current->scatters();
    const float dir_length = in_scattering_medium ? length(ray.dir) : 1.0f;
    FreeFlight flight;
    if (camera_segment && primary) {
      found = primary->found;
      if (found) scene.interaction(ray, primary->hit, &si, &cone);
      if (in_scattering_medium)
        flight = current->sample_free_flight(ray, found ? si.t * dir_length : kInfinity, throughput, sampler.get1d(),
                                             medium_rng);
    } else if (in_scattering_medium && current->homogeneous()) {
      // The distance first, then the surface searched for only up to it, as Cycles' random walk does: a walk in a
      // dense medium (subsurface scattering) mostly scatters before any surface, and a short ray is cheap to
      // trace and needs no hit record. In a homogeneous medium the flight is a function of its number alone until a
      // surface cuts it short, so it is the one that sampling to the surface would have drawn; a surface found
      // before it takes the crossing's weight, sampled again to that surface with the same number.
      const float u_flight = sampler.get1d();
      if (guided) {
        flight.t = guided->sample_distance(u_flight);
        flight.scattered = flight.t < kInfinity;
      } else {
        flight = current->sample_free_flight(ray, kInfinity, throughput, u_flight, medium_rng);
      }
      Ray search = ray;
      if (flight.scattered) search.tmax = std::min(ray.tmax, flight.t / dir_length);
      found = scene.intersect(search, &si, &cone);
      if (guided) {
        if (found) flight = FreeFlight{false, si.t * dir_length, Rgb(1)};
        flight.weight = guided->weight(flight.t, flight.scattered);
        guided.reset();
      } else if (found) {
        flight = current->sample_free_flight(ray, si.t * dir_length, throughput, u_flight, medium_rng);
      }
    } else {
      // A heterogeneous medium's flight (delta tracking) draws further numbers as it goes: it is sampled to the
      // surface.
      found = scene.intersect(ray, &si, &cone);
      if (in_scattering_medium)
        flight = current->sample_free_flight(ray, found ? si.t * dir_length : kInfinity, throughput, sampler.get1d(),
                                             medium_rng);
    }
    camera_segment = false;

    if (in_scattering_medium) {
      throughput *= flight.weight;
      if (is_black(throughput) || !is_finite(throughput)) break;
      if (flight.scattered) {
        if (volume_depth >= settings.max_volume_depth) break;
        ++volume_depth;
        const Vec3 p = ray.origin + ray.dir * (flight.t / dir_length);
        const Vec3 wo_world = -ray.dir / dir_length;
        if (features && !features->shaded) note_shading(*features, throughput, nullptr, Vec3(0), wo_world);
        straight = false;
        const HenyeyGreenstein phase = current->phase();
        // A shadow ray from inside an object's medium crosses the object's boundary; when no surface of the scene is
        // index-matched, every boundary blocks it, so the light sample would add nothing: it is not taken (its
        // numbers are spent all the same). A random walk under glass then traces one ray per step, not two.
        const bool sample_light =
            use_light_sampling && !lights.empty() && (scene.index_matched() || current == medium.outside());
        const auto [u_light_select, u_light] = light_numbers(sampler, sample_light);
        // The next direction: from the phase function, whose one lobe needs no choice; or, in a subsurface walk that
        // has met its surface, by the guided walk's mixture (guided_walk.h), the lobe's number choosing the channel
        // and the technique, the step's distance then drawn with the same pair.
        const GuidedWalk* guide = nullptr;  // the walk's constants, when this step is guided
        if (guiding && walk_normal && current->subsurface()) {
          if (!walk || &walk->medium() != current)
            if (const auto* homogeneous = dynamic_cast<const HomogeneousMedium*>(current)) walk.emplace(*homogeneous);
          if (walk && &walk->medium() == current) guide = &*walk;
        }
        PhaseSample ps;
        if (guide) {
          const float u_technique = sampler.get1d();
          guided.emplace(*guide, *walk_normal, wo_world, throughput, u_technique, sampler.get2d());
          // Light this direction finds is weighted against the light sample taken here by the phase function's
          // density, as the light sample is weighted against it: any pair of weights that sums to one keeps both
          // unbiased (Veach 1997, §9.2.2), whatever density drew the direction.
          ps = PhaseSample{guided->wi(), guided->phase()};
        } else {
          sampler.skip1d();
          ps = phase.sample(wo_world, sampler.get2d());
        }
        if (bounces == 0) first = 3;
        if (sample_light) {
          const Rgb c =
              throughput * direct_light_in_medium(scene, p, wo_world, phase, mis, u_light_select, u_light, medium,
                                                  ray.time, settings.max_volume_depth, medium_rng, counters);
          radiance += c;
          record(c, bounces + 1, false);
        }
        // Sampled exactly, the phase function's weight p / pdf is 1: the throughput goes on unchanged (a guided
        // step weights the direction with its distance, at the next flight).
        if (!(ps.pdf > 0)) break;
        cone.width = cone.width_at(flight.t);
        cone.spread = std::max(cone.spread, 2 / std::sqrt(kPi * ps.pdf));
        prev_delta = false;
        prev_pdf = ps.pdf;
        prev_p = p;
        if (depth + volume_depth >= settings.rr_start_depth) {
          // In a material's subsurface volume the walk is rouletted on its throughput alone: a floor on the
          // probability of ending it (kept elsewhere so that paths end even where nothing absorbs) would weight the
          // walks that survive hundreds of scatterings by 1 / 0.95^n, fireflies; max_volume_depth bounds the walk.
          // Cycles' random walk likewise ends a walk by its throughput (Chiang, Kutz and Burley 2016, §4).
          const float u_rr = sampler.get1d();
          const float q = std::max(current->subsurface() ? 0.0f : 0.05f, 1 - max_component(throughput) * eta_scale);
          if (u_rr < q) break;
          throughput /= 1 - q;
        } else {
          sampler.skip1d();
        }
        ray.origin = p;
        ray.dir = ps.wi;
        ray.tmin = 0;
        ray.tmax = kInfinity;
        ++counters.bounce;
        ++bounces;
        continue;
      }
    }

    if (!found) {
      // Escaping through the medium around the objects, the path takes its transmittance to infinity: none in a
      // channel that interacts at all (a path that escapes from inside an object's medium leaked through its
      // boundary and is not attenuated).
      if (!in_scattering_medium && current && current == medium.outside())
        medium.attenuate(throughput, ray, kInfinity, medium_rng);
      if (!scene.environment.black()) {
        if (prev_delta) {
          // Seen from the camera, directly or through mirrors and glass.
          const Rgb c = throughput * scene.environment.radiance(ray.dir);
          radiance += c;
          record(c, bounces, true);
        } else if (use_bsdf_hits) {
          // Light onto the last surface: the radiance light sampling estimates too, weighed against it (its density
          // from the same lookup).
          float pdf_dir = 0;
          const Rgb le = scene.environment.lighting(ray.dir, &pdf_dir);
          const Rgb c = throughput * le * (mis ? power_heuristic(prev_pdf, lights.environment_pmf() * pdf_dir) : 1.0f);
          radiance += c;
          record(c, bounces, true);
        }
      }
      break;
    }
    if (!in_scattering_medium) medium.attenuate(throughput, ray, si.t, medium_rng);
    const Vec3 wo_world = -ray.dir;
    if (si.material->emissive()) {
      Rgb le = si.material->emitted(si.sp, wo_world);
      if (!is_black(le)) {
        if (prev_delta) {
          const Rgb c = throughput * le;
          radiance += c;
          record(c, bounces, false);
        } else if (use_bsdf_hits) {
          float w = mis ? power_heuristic(prev_pdf, lights.pdf_hit(prev_p, si)) : 1.0f;
          const Rgb c = throughput * le * w;
          radiance += c;
          record(c, bounces, false);
        }
      }
    }
    if (si.material->index_matched()) {
      // An index-matched boundary: the path crosses it straight on into the medium beyond, not a bounce.
      if (volume_depth >= settings.max_volume_depth) break;
      ++volume_depth;
      if (features && straight) travelled += si.t * length(ray.dir);
      medium.refract(si.sp.front_face, si.material->interior());
      note_walk_surface(medium, si.sp.ng, ray.dir, walk_normal);
      cone.width = cone.width_at(si.t * length(ray.dir));
      ray.origin = offset_ray_origin(si.sp.p, si.sp.ng, ray.dir);
      ray.tmin = 0;
      ray.tmax = kInfinity;
      continue;
    }
    if (depth >= settings.max_depth) break;
    if (wavelength) {
      si.sp.wavelength_nm = wavelength->lambda_nm;
      if (si.material->dispersive() && !dispersed) {
        throughput *= wavelength->weight;
        dispersed = true;
      }
    }
    const Bsdf* bsdf = si.material->bsdf(si.sp, arena);
    if (features) {
      if (straight)
        note_surface(*features, si.sp, si.object, si.material_index, bsdf, travelled + si.t * length(ray.dir));
      if (!features->shaded && (!bsdf || has_non_delta(bsdf->flags())))
        note_shading(*features, throughput, bsdf, si.sp.frame.n, wo_world);
      straight = false;
    }
    if (!bsdf) break;
    const uint32_t flags = bsdf->flags();
    const Frame& frame = si.sp.frame;
    const Vec3 wo = frame.to_local(wo_world);
    if (wo.z == 0) break;

    // This vertex's numbers, in a fixed layout whatever the estimator or the material: the light sample's (spent
    // whether or not it is taken, and only computed when used), then the BSDF sample's.
    const bool sample_light = use_light_sampling && has_non_delta(flags) && !lights.empty();
    const auto [u_light_select, u_light] = light_numbers(sampler, sample_light);
    float u_lobe = 0;
    if (flags & kBsdfOneLobe)
      sampler.skip1d();
    else
      u_lobe = sampler.get1d();
    const Vec2 u_dir = sampler.get2d();
    // The BSDF is sampled before the light is: the two are independent, and in this order the processor overlaps
    // their arithmetic (3 % more samples per second on the Cornell box at one thread). The path goes on from the
    // sample after the light sample's contribution is added.
    const std::optional<BsdfSample> bs = bsdf->sample(wo, u_lobe, u_dir);

    // Next-event estimation: one light sample, unless every lobe is a delta (a light sample cannot hit it).
    const bool first_bounce = light && bounces == 0;
    if (first_bounce) {
      const Bsdf::LobeColors colors = bsdf->lobe_colors();
      light->color[0] += colors.diffuse;
      light->color[1] += colors.glossy;
      light->color[2] += colors.transmission;
    }
    if (sample_light) {
      LightSplit split;
      const Rgb c = throughput * direct_light(scene, si, *bsdf, flags, wo_world, wo, mis, u_light_select, u_light,
                                              medium, ray.time, settings.max_volume_depth, medium_rng, counters,
                                              first_bounce ? &split : nullptr);
      radiance += c;
      if (first_bounce) {
        // The first bounce's own light sample: direct light of each class its lobes give.
        const Rgb diffuse = throughput * split.diffuse;
        light->direct[0] += diffuse;
        light->direct[split.transmits ? 2 : 1] += c - diffuse;
      } else {
        record(c, bounces + 1, false);
      }
    }

    // Continue the path along the BSDF sample.
    if (!bs || !(bs->pdf > 0) || is_black(bs->f)) break;
    const Vec3 wi_world = frame.to_world(bs->wi);
    if (bounces == 0) first = lobe_class(bs->flags);
    // Reject directions whose shading and geometric sides disagree (shading normals can make these).
    const bool transmit = (bs->flags & kBsdfTransmission) != 0;
    if ((dot(wi_world, si.sp.ng) * dot(wo_world, si.sp.ng) > 0) == transmit) break;
    throughput *= bs->f * (std::abs(bs->wi.z) / bs->pdf);
    if (!is_finite(throughput)) break;
    if (transmit) {
      eta_scale *= sqr(bs->eta);
      medium.refract(si.sp.front_face, si.material->interior());
    }
    note_walk_surface(medium, si.sp.ng, wi_world, walk_normal);
    // The cone goes on from its width here. A lobe of density p spreads over a solid angle of about 1/p, a cone of
    // full angle 2 / sqrt(pi p): after a diffuse or glossy bounce textures are read as blurred as that lobe sees
    // them. A delta lobe keeps the spread (the surface's curvature is neglected).
    cone.width = cone.width_at(si.t * length(ray.dir));
    if (!is_delta(bs->flags)) cone.spread = std::max(cone.spread, 2 / std::sqrt(kPi * bs->pdf));
    prev_delta = is_delta(bs->flags);
    prev_pdf = bs->pdf;
    prev_p = si.sp.p;

    // Russian roulette on the throughput with the radiance-scaling of refraction removed.
    if (depth + 1 >= settings.rr_start_depth) {
      const float u_rr = sampler.get1d();
      float q = std::max(0.05f, 1 - max_component(throughput) * eta_scale);
      if (q > 0) {
        if (u_rr < q) break;
        throughput /= 1 - q;
      }
    } else {
      sampler.skip1d();
    }
    ray.origin = offset_ray_origin(si.sp.p, si.sp.ng, wi_world);
    ray.dir = wi_world;
    ray.tmin = 0;
    ray.tmax = kInfinity;
    ++counters.bounce;
    ++bounces;
    ++depth;
  }
  return radiance;
}

class PathIntegrator final : public Integrator {
 public:
  explicit PathIntegrator(const IntegratorSetup& setup) : Integrator(setup) {}

  void render_pass(uint32_t first_sample, uint32_t count, Film& film, const std::atomic<bool>& cancel,
                   const PixelMask* active) override {
    const AovWriter aovs(film, setup_.crypto.get());
    setup_.pool->parallel_for(tiles_.count(), [&](size_t tile, int w) {
      if (cancel.load(std::memory_order_relaxed)) return;
      render_tile(tiles_.tile(tile), worker(w), first_sample, count, film, aovs, active);
    });
  }

 private:
  // `active`, when given, marks the pixels that sample (the others are skipped).
  void render_tile(const PixelRegion& tile, Worker& worker, uint32_t first_sample, uint32_t sample_count, Film& film,
                   const AovWriter& aovs, const PixelMask* active);
};

void PathIntegrator::render_tile(const PixelRegion& tile, Worker& worker, uint32_t first_sample, uint32_t sample_count,
                                 Film& film, const AovWriter& aovs, const PixelMask* active) {
  const int x0 = tile.x, y0 = tile.y, x1 = tile.x + tile.width, y1 = tile.y + tile.height;
  ScratchArena& arena = worker.arena;
  // Counted on the stack and added once per tile (Integrator::Worker).
  RayCounters counters;
  uint64_t nonfinite = 0;
  const Scene& scene = *setup_.scene;
  const RayCone cone = setup_.camera.pixel_cone(setup_.samples_per_pixel);
  const bool dispersive = scene.dispersive();
  // Camera rays of up to kGroup neighbouring pixels in a row, at the same sample index, go to Embree as one packet:
  // they are coherent, and a packet traces them several times faster than one by one. Each pixel still gets its
  // samples in order, and its paths are those it would trace alone (up to Embree's rounding of sphere hits). With
  // adaptive sampling a packet holds the next kGroup pixels of the row that sample, whatever the threads.
  constexpr int kGroup = Accel::kPacketSize;
  const PixelSampler::SeedKeys seed_keys(setup_.seed);
  PixelSampler samplers[kGroup];
  Ray rays[kGroup];
  RayHit hits[kGroup];
  bool found[kGroup];
  int xs[kGroup];   // the packet's pixels' columns
  CameraAtTime at;  // a sample's time within the shutter, and the camera then
  for (int y = y0; y < y1; ++y) {
    const uint32_t row = static_cast<uint32_t>(y) * static_cast<uint32_t>(setup_.width);
    for (int gx = x0; gx < x1;) {
      int n = 0;
      if (!active) {
        for (; n < kGroup && gx < x1; ++gx) xs[n++] = gx;
      } else {
        for (; n < kGroup && gx < x1; ++gx)
          if ((*active)[row + static_cast<uint32_t>(gx)]) xs[n++] = gx;
        if (n == 0) continue;
      }
      for (uint32_t s = first_sample; s < first_sample + sample_count; ++s) {
        for (int i = 0; i < n; ++i) {
          PixelSampler& sampler = samplers[i];
          sampler = PixelSampler(seed_keys, row + static_cast<uint32_t>(xs[i]), s, setup_.sampler);
          camera_at_time(setup_, sampler, &at);
          Vec2 jitter = sampler.get2d();
          Vec2 lens;
          if (at.camera->uses_lens())
            lens = sampler.get2d();
          else
            sampler.skip2d();
          rays[i] = at.camera->generate_ray(
              Vec2(static_cast<float>(xs[i]) + jitter.x, static_cast<float>(y) + jitter.y), lens);
          rays[i].time = at.time;
        }
        scene.accel().intersect_packet(rays, n, hits, found);
        for (int i = 0; i < n; ++i) {
          const PrimaryHit primary{found[i], hits[i]};
          spectrum::WavelengthSample wavelength;
          if (dispersive) wavelength = spectrum::sample_wavelength(samplers[i].get1d_dimension0());
          SurfaceFeatures features;
          LightPassSample light;
          Rgb l = trace_path(scene, rays[i], &primary, samplers[i], setup_.settings, arena, counters, cone,
                             dispersive ? &wavelength : nullptr, aovs.wants_features() ? &features : nullptr,
                             aovs.wants_light() ? &light : nullptr);
          if (!is_finite(l) || l.x < 0 || l.y < 0 || l.z < 0) {
            ++nonfinite;
            l = Rgb(0);
            light = LightPassSample();  // dropped whole, as the beauty's sample is
          }
          film.add_sample(xs[i], y, l);
          if (!aovs.empty()) {
            aovs.add(film, xs[i], y, s, features, l);
            if (aovs.wants_light()) aovs.add_light(film, xs[i], y, light);
          }
        }
      }
    }
  }
  worker.rays += counters;
  worker.nonfinite += nonfinite;
}

}  // namespace

void register_path(IntegratorRegistry& registry) {
  registry.add("path", [](const IntegratorSetup& setup) { return std::make_unique<PathIntegrator>(setup); });
}

}  // namespace tessera
