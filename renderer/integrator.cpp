#include "renderer/integrator.h"

#include "renderer/scene.h"

namespace tessera {

const char* estimator_name(Estimator e) {
  switch (e) {
    case Estimator::kHemisphere: return "hemisphere";
    case Estimator::kArea: return "area";
    case Estimator::kMis: return "mis";
  }
  return "mis";
}

bool parse_estimator(const std::string& name, Estimator* out) {
  if (name == "hemisphere") *out = Estimator::kHemisphere;
  else if (name == "area") *out = Estimator::kArea;
  else if (name == "mis") *out = Estimator::kMis;
  else return false;
  return true;
}

namespace {

// Next-event estimation at a path vertex: one light sample's contribution, before the path's throughput, weighed
// against BSDF sampling by the power heuristic with `mis`.
Rgb direct_light(const Scene& scene, const SurfaceInteraction& si, const Bsdf& bsdf, uint32_t flags,
                 const Vec3& wo_world, const Vec3& wo, bool mis, float u_select, Vec2 u, RayCounters& counters) {
  LightSample ls;
  if (!scene.lights().sample(scene, si.sp.p, u_select, u, &ls) || !(ls.pdf > 0) || is_black(ls.radiance)) return {};
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
  Ray shadow;
  shadow.origin = offset_ray_origin(si.sp.p, si.sp.ng, ls.wi);
  shadow.tmin = 0;
  if (std::isinf(ls.dist)) {
    shadow.dir = ls.wi;
    shadow.tmax = kInfinity;
  } else {
    // Aim from the offset origin at a target offset off the light's surface, with an unnormalised direction so that
    // t = 1 is the target: both ends are clear of self-intersection.
    const Vec3 target = is_black(ls.n_light) ? ls.p_light : offset_ray_origin(ls.p_light, ls.n_light, -ls.wi);
    shadow.dir = target - shadow.origin;
    shadow.tmax = 1 - 1e-5f;
  }
  ++counters.shadow;
  if (scene.occluded(shadow)) return {};
  const float w = weigh ? power_heuristic(ls.pdf, bsdf_pdf) : 1.0f;
  return f * ls.radiance * (w / ls.pdf);
}

}  // namespace

Rgb trace_path(const Scene& scene, const Ray& camera_ray, const PrimaryHit* primary, PixelSampler& sampler,
               const IntegratorSettings& settings, ScratchArena& arena, RayCounters& counters, RayCone cone) {
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
  float eta_scale = 1;  // product of eta^2 across refractions, kept out of Russian roulette
  Rgb sigma_a(0);       // absorption of the medium the path is travelling through (zero: vacuum)
  ++counters.camera;

  for (int depth = 0;; ++depth) {
    arena.reset();
    SurfaceInteraction si;
    bool found;
    if (depth == 0 && primary) {
      found = primary->found;
      if (found) scene.interaction(ray, primary->hit, &si, &cone);
    } else {
      found = scene.intersect(ray, &si, &cone);
    }
    if (!found) {
      if (!scene.environment.black()) {
        if (prev_delta) {
          // Seen from the camera, directly or through mirrors and glass.
          radiance += throughput * scene.environment.radiance(ray.dir);
        } else if (use_bsdf_hits) {
          // Light onto the last surface: the radiance light sampling estimates too, weighed against it (its density
          // from the same lookup).
          float pdf_dir = 0;
          const Rgb le = scene.environment.lighting(ray.dir, &pdf_dir);
          radiance += throughput * le * (mis ? power_heuristic(prev_pdf, lights.environment_pmf() * pdf_dir) : 1.0f);
        }
      }
      break;
    }
    if (!is_black(sigma_a)) {
      // Beer-Lambert attenuation over the segment inside an absorbing object.
      const float d = si.t * length(ray.dir);
      throughput *= Rgb(std::exp(-sigma_a.x * d), std::exp(-sigma_a.y * d), std::exp(-sigma_a.z * d));
    }
    const Vec3 wo_world = -ray.dir;
    if (si.material->emissive()) {
      Rgb le = si.material->emitted(si.sp, wo_world);
      if (!is_black(le)) {
        if (prev_delta) {
          radiance += throughput * le;
        } else if (use_bsdf_hits) {
          float w = mis ? power_heuristic(prev_pdf, lights.pdf_hit(scene, prev_p, si)) : 1.0f;
          radiance += throughput * le * w;
        }
      }
    }
    if (depth >= settings.max_depth) break;
    const Bsdf* bsdf = si.material->bsdf(si.sp, arena);
    if (!bsdf) break;
    const uint32_t flags = bsdf->flags();
    const Frame& frame = si.sp.frame;
    const Vec3 wo = frame.to_local(wo_world);
    if (wo.z == 0) break;

    // This vertex's numbers, in a fixed layout whatever the estimator or the material: the light sample's (spent
    // whether or not it is taken, and only computed when used), then the BSDF sample's.
    const bool sample_light = use_light_sampling && has_non_delta(flags) && !lights.empty();
    float u_light_select = 0;
    Vec2 u_light;
    if (sample_light) {
      u_light_select = sampler.get1d();
      u_light = sampler.get2d();
    } else {
      sampler.skip1d();
      sampler.skip2d();
    }
    float u_lobe = 0;
    if (flags & kBsdfOneLobe) sampler.skip1d();
    else u_lobe = sampler.get1d();
    const Vec2 u_dir = sampler.get2d();
    // The BSDF is sampled before the light is: the two are independent, and in this order the processor overlaps
    // their arithmetic (3 % more samples per second on the Cornell box at one thread). The path goes on from the
    // sample after the light sample's contribution is added.
    const std::optional<BsdfSample> bs = bsdf->sample(wo, u_lobe, u_dir);

    // Next-event estimation: one light sample, unless every lobe is a delta (a light sample cannot hit it).
    if (sample_light) {
      radiance += throughput * direct_light(scene, si, *bsdf, flags, wo_world, wo, mis, u_light_select, u_light,
                                            counters);
    }

    // Continue the path along the BSDF sample.
    if (!bs || !(bs->pdf > 0) || is_black(bs->f)) break;
    const Vec3 wi_world = frame.to_world(bs->wi);
    // Reject directions whose shading and geometric sides disagree (shading normals can make these).
    const bool transmit = (bs->flags & kBsdfTransmission) != 0;
    if ((dot(wi_world, si.sp.ng) * dot(wo_world, si.sp.ng) > 0) == transmit) break;
    throughput *= bs->f * (std::abs(bs->wi.z) / bs->pdf);
    if (!is_finite(throughput)) break;
    if (transmit) {
      eta_scale *= sqr(bs->eta);
      // Refracting in through the front side enters the object's medium; through the back side leaves it.
      sigma_a = si.sp.front_face ? si.material->volume_sigma_a : Rgb(0);
    }
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
  }
  return radiance;
}

}  // namespace tessera
