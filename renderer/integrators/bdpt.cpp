// Light tracing (`light`) and bidirectional path tracing (`bdpt`): the adjoint face of light transport (emitted
// importance W_e and the measurement equation: Dutre, Bala & Bekaert, Advanced Global Illumination, 2nd ed., 2.8;
// Veach 1997, ch. 4 and 10).
//
// Every pixel sample builds a camera subpath (the camera's vertex, then surfaces found by sampling BSDFs, in radiance
// mode) and a light subpath (a point on a light, then surfaces found by sampling the adjoint BSDFs, in importance
// mode). Joining the first s vertices of the light subpath to the first t of the camera subpath gives a path of
// s + t vertices for every (s, t): s = 0 is a camera path that hits an emitter, s = 1 joins the camera path to a
// point sampled on a light (next-event estimation), t = 1 joins the light subpath to a point sampled on the lens
// and splats the result where it lands on the film (light tracing). BDPT weights every strategy by the power
// heuristic, computed from the ratios of the densities with which the neighbouring strategies would have sampled the
// same path (Veach 1997, 10.2 and 10.3.4; pbrt-v4, 13.4.4): no product of densities is ever formed, so nothing
// overflows. Densities are by area, or by solid angle for vertices at infinity; a vertex whose sampling is a delta
// (a specular bounce, a point or directional light) cannot be joined, and the strategies that would need to are
// left out of the sum. Russian roulette ends subpaths unbiasedly; the weights leave it out (they are any functions
// of the path that sum to 1 over the strategies that can make it).
//
// In participating media (medium.h) both subpaths sample free flights, and a scattering event is a vertex whose phase
// function takes the BSDF's place; segments that join vertices take the media's transmittance, crossing `interface`
// boundaries as shadow rays do (Lafortune and Willems 1996, "Rendering participating media with bidirectional path
// tracing"; Pharr, Jakob and Humphreys, PBR 3rd ed., §16.3.1 and 16.3.4). The densities the weights compare are the
// directions' (phase or BSDF, by area); the free flights' distance densities are left out of them as pbrt-v3 leaves
// them out, which keeps the weights a function of the path that sums to 1 over the strategies, so the estimate stays
// unbiased. A walk passes through index-matched boundaries without a vertex. Medium vertices count towards
// render.max_volume_depth, not max_depth.
//
// `light` keeps only the t = 1 strategies, unweighted: light tracing. It does not see lights at infinity directly
// (the environment appears black) nor anything seen only through mirrors and glass.
//
// Pixel measurement: a pixel's importance is width x height times the camera's W_e over the rays that land in it
// (Camera::importance). One light subpath is traced per pixel sample of the region; a splat is weighted by the
// image's pixel count over the region's, so the light paths of a crop estimate the same pixels.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "renderer/aov.h"
#include "renderer/integrator.h"
#include "renderer/scene.h"
#include "renderer/spectrum.h"
#include "renderer/thread_pool.h"

namespace tessera {

namespace {

enum class VertexKind : uint8_t { kCamera, kLight, kSurface, kMedium };

struct Vertex {
  VertexKind kind = VertexKind::kSurface;
  Rgb beta;     // the subpath's throughput up to this vertex (its measurement contribution over its density)
  Vec3 p;       // position (unused for a light at infinity)
  Vec3 ng;      // geometric normal; zero for points (camera, point and spot lights) and lights at infinity
  Frame frame;  // shading frame (surfaces)
  Vec3 wo;      // unit direction towards the previous vertex (surfaces)
  const Bsdf* bsdf = nullptr;
  // The medium it scattered in (medium vertices) or was reached through (surfaces).
  const Medium* medium = nullptr;
  int volume = 0;   // medium vertices on its subpath up to and including it
  ShadingPoint sp;  // the surface point, for its emission
  const Material* material = nullptr;
  uint32_t object = 0, material_index = 0;  // SurfaceInteraction's (surfaces)
  uint32_t light = kNoLight;                // the light this vertex is on (light vertices, emitting surfaces)
  bool delta = false;                       // scattered by a delta lobe
  int8_t lobe = -1;          // the lobe class it scattered by (lobe_class), for the light passes; -1 none
  bool dispersed = false;    // a dispersive material among its subpath's surface vertices up to this one
  bool delta_light = false;  // a point, spot or directional light
  bool infinite = false;     // a light at infinity: `dir` is the direction its light travels
  Vec3 dir;
  // Densities of sampling this vertex from the previous one on its own subpath (fwd) and from the next one in the
  // reverse direction (rev), by area (by solid angle for a vertex at infinity).
  float pdf_fwd = 0, pdf_rev = 0;

  bool on_surface() const { return !is_black(ng); }
  bool is_light() const { return kind == VertexKind::kLight || (kind == VertexKind::kSurface && light != kNoLight); }
  bool connectible() const {
    switch (kind) {
      case VertexKind::kCamera:
        return true;
      case VertexKind::kLight:
        return !(infinite && delta_light);  // a directional light's direction is fixed
      case VertexKind::kSurface:
        return bsdf && has_non_delta(bsdf->flags());
      case VertexKind::kMedium:
        return true;
    }
    return false;
  }
};

// A density by solid angle at `from` turned into one by area at `to` (unchanged for a vertex at infinity).
float to_area(float pdf, const Vertex& from, const Vertex& to) {
  if (to.infinite) return pdf;
  const Vec3 w = to.p - from.p;
  const float d2 = length_squared(w);
  if (!(d2 > 0)) return 0;
  if (to.on_surface()) pdf *= std::abs(dot(to.ng, w)) / std::sqrt(d2);
  return pdf / d2;
}

// Unit direction from vertex a towards vertex b (b may be at infinity).
Vec3 direction_to(const Vertex& a, const Vertex& b) {
  if (b.infinite) return -b.dir;
  return normalize(b.p - a.p);
}

struct Context {
  const Scene& scene;
  const Camera& camera;  // at the sample's time
  const IntegratorSettings& settings;
  float disc_pdf;  // area density of the origins of light from infinity
  // The camera sample's time within the shutter (motion blur): every ray of both subpaths and of their connections is
  // traced at it, so that a path sees the scene at one instant.
  float time = 0;
  // The pixel sample's stream of further numbers for media from grids (medium.h), shared by its walks and joins.
  MediumRng* medium_rng = nullptr;
};

// The medium light crosses leaving vertex v along w: the one a medium vertex is in; the one around the objects at the
// camera and the lights; at a surface, the one it was reached through when w leaves on that side, else the one
// beyond it as MediumTracker::refract finds it.
const Medium* medium_towards(const Context& c, const Vertex& v, const Vec3& w) {
  switch (v.kind) {
    case VertexKind::kMedium:
      return v.medium;
    case VertexKind::kCamera:
    case VertexKind::kLight:
      return c.scene.medium.get();
    case VertexKind::kSurface:
      break;
  }
  if ((dot(w, v.ng) > 0) == (dot(v.wo, v.ng) > 0)) return v.medium;
  MediumTracker beyond = MediumTracker::starting_in(v.medium, c.scene.medium.get());
  beyond.refract(dot(v.wo, v.ng) > 0, v.material->interior());
  return beyond.current();
}

// The cosine a vertex's scattering weighs light along w by: at a surface the shading normal's; none in a medium.
float cos_at(const Vertex& v, const Vec3& w) {
  return v.kind == VertexKind::kMedium ? 1.0f : std::abs(dot(v.frame.n, w));
}

// The BSDF at surface vertex v for light leaving towards `next`, with the shading-normal correction of importance
// transport (Veach 1997, 5.3: |wo.ns| |wi.ng| / (|wo.ng| |wi.ns|)); zero where the shading and geometric normals
// disagree on the side of wi.
Rgb vertex_f(const Vertex& v, const Vec3& wi, TransportMode mode) {
  if (v.kind == VertexKind::kMedium) return Rgb(v.medium->phase().p(v.wo, wi));  // symmetric: no adjoint to take
  const Vec3 wo_l = v.frame.to_local(v.wo), wi_l = v.frame.to_local(wi);
  const float go = dot(v.wo, v.ng), gi = dot(wi, v.ng);
  if ((go * gi > 0) != (wo_l.z * wi_l.z > 0)) return Rgb(0);
  Rgb f = v.bsdf->eval_for(mode, wo_l, wi_l);
  if (mode == TransportMode::kImportance) {
    const float denom = std::abs(go) * std::abs(wi_l.z);
    if (!(denom > 0)) return Rgb(0);
    f *= std::abs(wo_l.z) * std::abs(gi) / denom;
  }
  return f;
}

// The area density with which the light at `v` (a light vertex or an emitting surface) emits towards `next`, given
// the light's choice and origin.
float pdf_light(const Context& c, const Vertex& v, const Vertex& next) {
  if (v.infinite) {
    // From the disc of the scene's bounding sphere, by area across the beam, onto next's surface.
    float pdf = c.disc_pdf;
    if (next.on_surface()) pdf *= std::abs(dot(next.ng, v.dir));
    return pdf;
  }
  const Vec3 d = next.p - v.p;
  const float d2 = length_squared(d);
  if (!(d2 > 0)) return 0;
  const Vec3 w = d / std::sqrt(d2);
  float pdf_pos, pdf_dir;
  c.scene.lights().emission_pdf(v.light, v.ng, w, &pdf_pos, &pdf_dir);
  float pdf = pdf_dir / d2;
  if (next.on_surface()) pdf *= std::abs(dot(next.ng, w));
  return pdf;
}

// The density of choosing the light at `v` and its origin there (for lights at infinity: of the direction, by solid
// angle, including the environment's choice; a directional light's direction has none).
float pdf_light_origin(const Context& c, const Vertex& v, const Vertex& next) {
  const LightSet& lights = c.scene.lights();
  if (v.infinite) {
    if (v.delta_light || lights.environment_light() == kNoLight) return 0;
    float pdf_pos, pdf_dir;
    lights.emission_pdf(lights.environment_light(), Vec3(0), v.dir, &pdf_pos, &pdf_dir);
    return lights.environment_pmf() * pdf_dir;
  }
  float pdf_pos, pdf_dir;
  lights.emission_pdf(v.light, v.ng, direction_to(v, next), &pdf_pos, &pdf_dir);
  return pdf_pos;
}

// The area density with which vertex v, reached from `prev`, samples `next` (Veach 1997, 10.2).
float vertex_pdf(const Context& c, const Vertex& v, const Vertex* prev, const Vertex& next) {
  if (v.kind == VertexKind::kLight) return pdf_light(c, v, next);
  const Vec3 wn = direction_to(v, next);
  float pdf = 0;
  if (v.kind == VertexKind::kCamera) {
    Ray ray;
    ray.origin = v.p;
    ray.dir = wn;
    float pdf_pos;
    c.camera.importance_pdf(ray, &pdf_pos, &pdf);
  } else if (v.kind == VertexKind::kMedium) {
    if (!prev) return 0;
    pdf = v.medium->phase().pdf(direction_to(v, *prev), wn);
  } else {
    if (!prev || !v.bsdf) return 0;
    pdf = v.bsdf->pdf(v.frame.to_local(direction_to(v, *prev)), v.frame.to_local(wn));
  }
  return to_area(pdf, v, next);
}

// What the render passes record of a camera subpath of n vertices (note_surface, note_shading): its first drawn
// surface, reached along the camera ray past index-matched boundaries, and its first surface whose BSDF is not wholly
// a delta lobe.
void camera_features(const Vertex* camera, int n, SurfaceFeatures* f) {
  bool straight = true;
  for (int i = 1; i < n; ++i) {
    const Vertex& v = camera[i];
    if (v.kind == VertexKind::kMedium) {
      // A scattering event in a medium: shaded by the throughput alone, and the camera ray is not followed past it.
      note_shading(*f, v.beta, nullptr, Vec3(0), v.wo);
      return;
    }
    if (v.kind != VertexKind::kSurface) return;
    const bool crossing = v.material->index_matched();
    if (straight && !crossing) {
      note_surface(*f, v.sp, v.object, v.material_index, v.bsdf, length(v.p - camera[0].p));
      straight = false;
    }
    if (!v.bsdf || has_non_delta(v.bsdf->flags())) {
      note_shading(*f, v.beta, v.bsdf, v.frame.n, v.wo);
      return;
    }
  }
}

// The light passes' share of a strategy's contribution `c` (aov.h): its scattering vertices k = s + t - 2 and its
// first bounce (camera[1], or for t = 1 the light subpath's vertex the lens sees) say where it goes: emission or
// background for k = 0; the first bounce's class, direct for k = 1 and indirect after. Where the first bounce is the
// vertex that joins the strategy's two ends (`joined`), its BSDF's diffuse part goes to diffuse and the rest to
// glossy or transmission (Bsdf::eval_diffuse), as the path tracer splits its first light sample: light arrives at
// `first` from direction `toward_light` and leaves towards `toward_eye`. Otherwise the class is the lobe `first`
// sampled.
void record_light(LightPassSample& lp, const Vertex& first, const Vec3& toward_light, const Vec3& toward_eye,
                  bool joined, int k, const Rgb& c) {
  if (first.kind == VertexKind::kMedium) {
    (k == 1 ? lp.volume_direct : lp.volume_indirect) += c;
    return;
  }
  Rgb* direct_or_indirect = k == 1 ? lp.direct : lp.indirect;
  if (!joined) {
    if (first.lobe >= 0) direct_or_indirect[first.lobe] += c;
    return;
  }
  const Vec3 wo = first.frame.to_local(toward_eye), wi = first.frame.to_local(toward_light);
  const Rgb f = first.bsdf->eval(wo, wi), d = first.bsdf->eval_diffuse(wo, wi);
  const Rgb diffuse(f.x > 0 ? c.x * (d.x / f.x) : 0, f.y > 0 ? c.y * (d.y / f.y) : 0, f.z > 0 ? c.z * (d.z / f.z) : 0);
  const bool transmits = dot(toward_light, first.ng) * dot(toward_eye, first.ng) < 0;
  direct_or_indirect[0] += diffuse;
  direct_or_indirect[transmits ? 2 : 1] += c - diffuse;
}

// The fraction of light that crosses the segment between two finite vertices, each end offset off its surface: zero
// where a surface blocks it, else the media's transmittance along it (shadow_transmittance, from a's side).
Rgb transmittance(const Context& c, const Vertex& a, const Vertex& b, RayCounters& counters) {
  Ray ray;
  ray.time = c.time;
  const Vec3 d = b.p - a.p;
  ray.origin = a.on_surface() ? offset_ray_origin(a.p, a.ng, d) : a.p;
  const Vec3 target = b.on_surface() ? offset_ray_origin(b.p, b.ng, -d) : b.p;
  ray.dir = target - ray.origin;
  ray.tmin = 0;
  ray.tmax = 1 - 1e-5f;
  const MediumTracker medium = MediumTracker::starting_in(medium_towards(c, a, d), c.scene.medium.get());
  return shadow_transmittance(c.scene, ray, medium, c.settings.max_volume_depth, *c.medium_rng, counters);
}

// Russian roulette on the throughput relative to the subpath's start `beta_ref`, from the vertex count
// rr_start_depth on (`n` vertices so far): false when the walk ends, else `beta` takes the survival's weight.
bool survives_roulette(const Context& c, int n, Rgb& beta, float eta_scale, float beta_ref, float u_rr) {
  if (n < c.settings.rr_start_depth) return true;
  const float q = std::max(0.05f, 1 - max_component(beta) * eta_scale / beta_ref);
  if (u_rr < q) return false;
  beta /= 1 - q;
  return true;
}

// The subpath's walk from its endpoint (Veach 1997, 10.2): vertices path[1..] after path[0], the endpoint; returns
// how many. It ends at its max_surfaces-th surface vertex, or when its medium vertices and crossings of index-matched
// boundaries would pass max_volume_depth. `beta` and `pdf_dir` are the throughput and the solid-angle density of the
// ray leaving the endpoint. Camera subpaths that leave the scene end at the environment, as a light vertex.
// `wavelength_nm` is the pixel sample's, for dispersive BSDFs (0: none). A walk `from_infinity` (a light at infinity)
// brings light from infinitely far through the medium around the objects: its first segment takes that medium's
// transmittance to infinity (none in a channel that interacts, as the path tracer's escaping paths take) and samples
// no free flight.
int random_walk(const Context& c, Ray ray, Rgb beta, float pdf_dir, int max_surfaces, TransportMode mode,
                float wavelength_nm, bool from_infinity, PixelSampler& sampler, ScratchArena& arena, Vertex* path,
                RayCounters& counters) {
  if (max_surfaces <= 0) return 0;
  const Scene& scene = c.scene;
  const float beta_ref = std::max(max_component(beta), 1e-30f);
  float pdf_fwd = pdf_dir;
  float eta_scale = 1;                       // radiance's eta^2 across refractions, kept out of Russian roulette
  MediumTracker medium(scene.medium.get());  // the medium the walk is in
  MediumRng& rng = *c.medium_rng;
  int n = 0, surfaces = 0;
  int volume_steps = 0;  // medium vertices and boundary crossings
  for (bool first_segment = true;; first_segment = false) {
    Vertex& prev = path[n];
    SurfaceInteraction si;
    const bool found = scene.intersect(ray, &si);
    const Medium* current = medium.current();
    if (current && first_segment && from_infinity) {
      medium.attenuate(beta, ray, kInfinity, rng);
    } else if (current && current->scatters()) {
      // A free flight (medium.h): a scattering event before the surface is a medium vertex.
      const float dir_length = length(ray.dir);
      const FreeFlight flight =
          current->sample_free_flight(ray, found ? si.t * dir_length : kInfinity, beta, sampler.get1d(), rng);
      beta *= flight.weight;
      if (flight.scattered) {
        if (is_black(beta) || !is_finite(beta) || volume_steps >= c.settings.max_volume_depth) break;
        ++volume_steps;
        Vertex& v = path[n + 1];
        v = Vertex();
        v.kind = VertexKind::kMedium;
        v.medium = current;
        v.p = ray.origin + ray.dir * (flight.t / dir_length);
        v.wo = -ray.dir / dir_length;
        v.beta = beta;
        v.dispersed = prev.dispersed;
        v.volume = prev.volume + 1;
        v.pdf_fwd = to_area(pdf_fwd, prev, v);
        ++n;
        sampler.skip1d();  // a surface's lobe choice: a phase function has one lobe
        const Vec2 u_dir = sampler.get2d();
        const float u_rr = sampler.get1d();
        // Sampled exactly, the phase function's weight p / pdf is 1; p is symmetric, so the reverse density is the
        // forward one.
        const PhaseSample ps = current->phase().sample(v.wo, u_dir);
        if (!(ps.pdf > 0)) break;
        pdf_fwd = ps.pdf;
        prev.pdf_rev = to_area(ps.pdf, v, prev);
        if (!survives_roulette(c, n, beta, eta_scale, beta_ref, u_rr)) break;
        ray.origin = v.p;
        ray.dir = ps.wi;
        ray.tmin = 0;
        ray.tmax = kInfinity;
        ++counters.bounce;
        continue;
      }
    } else if (current && (found || current == medium.outside())) {
      // Escaping, a path takes the transmittance to infinity of the medium around the objects only.
      medium.attenuate(beta, ray, found ? si.t : kInfinity, rng);
    }
    if (is_black(beta)) break;
    if (!found) {
      if (mode == TransportMode::kRadiance && !scene.environment.black()) {
        Vertex& v = path[n + 1];
        v = Vertex();
        v.kind = VertexKind::kLight;
        v.infinite = true;
        v.dir = -ray.dir;
        v.beta = beta;
        v.pdf_fwd = pdf_fwd;
        v.light = scene.lights().environment_light();
        v.volume = prev.volume;
        ++n;
      }
      break;
    }
    if (si.material->index_matched()) {
      // An index-matched boundary is crossed straight on into the medium beyond, without a vertex.
      if (volume_steps >= c.settings.max_volume_depth) break;
      ++volume_steps;
      medium.refract(si.sp.front_face, si.material->interior());
      ray.origin = offset_ray_origin(si.sp.p, si.sp.ng, ray.dir);
      ray.tmin = 0;
      ray.tmax = kInfinity;
      continue;
    }
    Vertex& v = path[n + 1];
    v = Vertex();
    v.kind = VertexKind::kSurface;
    v.medium = current;
    si.sp.wavelength_nm = wavelength_nm;
    v.dispersed = prev.dispersed || si.material->dispersive();
    v.volume = prev.volume;
    v.p = si.sp.p;
    v.ng = si.sp.ng;
    v.frame = si.sp.frame;
    v.wo = -ray.dir;
    v.sp = si.sp;
    v.material = si.material;
    v.object = si.object;
    v.material_index = si.material_index;
    v.light = si.light;
    v.beta = beta;
    v.pdf_fwd = to_area(pdf_fwd, prev, v);
    v.bsdf = si.material->bsdf(si.sp, arena);
    ++n;
    if (++surfaces >= max_surfaces || !v.bsdf) break;
    const Vec3 wo = v.frame.to_local(v.wo);
    if (wo.z == 0) break;
    const float u_lobe = sampler.get1d();
    const Vec2 u_dir = sampler.get2d();
    const float u_rr = sampler.get1d();
    const std::optional<BsdfSample> bs = v.bsdf->sample_for(mode, wo, u_lobe, u_dir);
    if (!bs || !(bs->pdf > 0) || is_black(bs->f)) break;
    const Vec3 wi = v.frame.to_world(bs->wi);
    v.lobe = static_cast<int8_t>(lobe_class(bs->flags));
    const bool transmit = (bs->flags & kBsdfTransmission) != 0;
    if ((dot(wi, v.ng) * dot(v.wo, v.ng) > 0) == transmit) break;
    beta *= bs->f * (std::abs(bs->wi.z) / bs->pdf);
    if (mode == TransportMode::kImportance) {
      const float denom = std::abs(dot(v.wo, v.ng)) * std::abs(bs->wi.z);
      if (!(denom > 0)) break;
      beta *= std::abs(wo.z) * std::abs(dot(wi, v.ng)) / denom;
    }
    if (!is_finite(beta)) break;
    pdf_fwd = bs->pdf;
    float pdf_rev = v.bsdf->pdf(bs->wi, wo);
    if (is_delta(bs->flags)) {
      v.delta = true;
      pdf_fwd = pdf_rev = 0;
    }
    if (transmit) {
      if (mode == TransportMode::kRadiance) eta_scale *= sqr(bs->eta);
      medium.refract(si.sp.front_face, si.material->interior());
    }
    prev.pdf_rev = to_area(pdf_rev, v, prev);
    if (!survives_roulette(c, n, beta, eta_scale, beta_ref, u_rr)) break;
    ray.origin = offset_ray_origin(v.p, v.ng, wi);
    ray.dir = wi;
    ray.tmin = 0;
    ray.tmax = kInfinity;
    ++counters.bounce;
  }
  return n;
}

// Temporarily replaces a value, restoring it when it goes out of scope.
template <typename T>
class Scoped {
 public:
  Scoped() = default;
  Scoped(T* target, T value) : target_(target), saved_(*target) { *target = value; }
  Scoped(const Scoped&) = delete;
  Scoped& operator=(Scoped&& o) noexcept {
    restore();
    target_ = o.target_;
    saved_ = o.saved_;
    o.target_ = nullptr;
    return *this;
  }
  ~Scoped() { restore(); }

 private:
  void restore() {
    if (target_) *target_ = saved_;
    target_ = nullptr;
  }
  T* target_ = nullptr;
  T saved_{};
};

// The power-heuristic weight of strategy (s, t) for the path it made (Veach 1997, 10.3.4 and 9.2.4), from the
// ratios p_i / p_s of the densities of the neighbouring strategies, each found from the one before by one vertex's
// reverse and forward densities. `sampled` is the vertex strategies s = 1 and t = 1 sampled afresh: it stands in for
// light[0] or camera[0]. The path's vertices are read in place; the few densities the join changes are replaced for
// the weight's evaluation and restored after it (pbrt-v4, 13.4.4), so no vertex is copied.
float mis_weight(const Context& c, Vertex* light, Vertex* camera, Vertex& sampled, int s, int t) {
  if (s + t == 2) return 1;
  auto remap0 = [](float f) { return f != 0 ? f : 1.0f; };
  Vertex* qs = s == 1 ? &sampled : s > 1 ? &light[s - 1] : nullptr;
  Vertex* pt = t == 1 ? &sampled : t > 1 ? &camera[t - 1] : nullptr;
  Vertex* qs_minus = s > 1 ? &light[s - 2] : nullptr;
  Vertex* pt_minus = t > 1 ? &camera[t - 2] : nullptr;
  // The joined vertices are joined, whatever they scattered by.
  Scoped<bool> a2, a3;
  if (pt) a2 = Scoped<bool>(&pt->delta, false);
  if (qs) a3 = Scoped<bool>(&qs->delta, false);
  // The reverse densities the join makes: of the ends' neighbours, through the other subpath.
  Scoped<float> a4, a5, a6, a7;
  if (pt)
    a4 = Scoped<float>(&pt->pdf_rev, s > 0 ? vertex_pdf(c, *qs, qs_minus, *pt) : pdf_light_origin(c, *pt, *pt_minus));
  if (pt_minus)
    a5 = Scoped<float>(&pt_minus->pdf_rev, s > 0 ? vertex_pdf(c, *pt, qs, *pt_minus) : pdf_light(c, *pt, *pt_minus));
  if (qs) a6 = Scoped<float>(&qs->pdf_rev, vertex_pdf(c, *pt, pt_minus, *qs));
  if (qs_minus) a7 = Scoped<float>(&qs_minus->pdf_rev, vertex_pdf(c, *qs, pt, *qs_minus));
  // The camera side's vertices 1..t-1 are all the subpath's own (sampled replaces only camera[0], which has no term).
  float sum = 0, r = 1;
  for (int i = t - 1; i > 0; --i) {
    r *= sqr(remap0(camera[i].pdf_rev) / remap0(camera[i].pdf_fwd));
    if (!camera[i].delta && !camera[i - 1].delta) sum += r;
  }
  r = 1;
  for (int i = s - 1; i >= 0; --i) {
    const Vertex& v = i == s - 1 ? *qs : light[i];
    r *= sqr(remap0(v.pdf_rev) / remap0(v.pdf_fwd));
    const bool delta_before = i > 0 ? light[i - 1].delta : v.delta_light;
    if (!v.delta && !delta_before) sum += r;
  }
  return 1 / (1 + sum);
}

class BidirectionalIntegrator final : public Integrator {
 public:
  BidirectionalIntegrator(const IntegratorSetup& setup, bool light_only) : Integrator(setup), light_only_(light_only) {
    const std::string problem = integrator_camera_problem(setup_.settings.name, setup_.camera);
    if (!problem.empty()) throw std::invalid_argument(problem);
    const double image = static_cast<double>(setup_.width) * setup_.height;
    const double region = static_cast<double>(setup_.region.width) * setup_.region.height;
    splat_scale_ = region > 0 ? static_cast<float>(image / region) : 1.0f;
    const float r = std::max(setup_.scene->bounds().radius(), 1e-3f);
    disc_pdf_ = 1 / (kPi * r * r);
    // Camera subpaths: the camera and up to max_depth + 1 surfaces (the last may only emit); light subpaths: the
    // light and up to max_depth surfaces; in a scene whose media scatter, either with up to max_volume_depth medium
    // vertices besides.
    const size_t volume = setup_.scene->scattering() ? static_cast<size_t>(setup_.settings.max_volume_depth) : 0;
    const size_t per_worker = (static_cast<size_t>(setup_.settings.max_depth) + 2 + volume) * 2;
    for (int i = 0; i < setup_.pool->size(); ++i) vertices_.emplace_back(per_worker);
  }

  bool measures_noise() const override { return !light_only_; }

  void render_pass(uint32_t first_sample, uint32_t count, Film& film, const std::atomic<bool>& cancel,
                   const PixelMask* active) override {
    if (active) throw std::invalid_argument(integrator_adaptive_problem(light_only_ ? "light" : "bdpt"));
    const AovWriter aovs(film, setup_.crypto.get());
    setup_.pool->parallel_for(tiles_.count(), [&](size_t tile, int w) {
      if (cancel.load(std::memory_order_relaxed)) return;
      render_tile(tiles_.tile(tile), w, first_sample, count, film, aovs);
    });
  }

 private:
  void render_tile(const PixelRegion& tile, int w, uint32_t first_sample, uint32_t count, Film& film,
                   const AovWriter& aovs);
  // The pixel sample's contribution to its own pixel; splats land on the film directly. `wavelength`, in a scene with
  // dispersive materials, is the sample's (spectrum.h).
  // `features`, when given, receives what the render passes record of the camera subpath, and `lp` the light
  // passes' split of the pixel's own contributions (splats go to the film at once, through `aovs`).
  Rgb sample(const Context& c, Vec2 film_pos, PixelSampler& sampler, ScratchArena& arena, Vertex* camera, Vertex* light,
             Film& film, RayCounters& counters, const spectrum::WavelengthSample* wavelength, SurfaceFeatures* features,
             LightPassSample* lp, const AovWriter& aovs);
  // The unweighted contribution of strategy (s, t), and through `sampled` and `splat_at` the vertex it sampled
  // afresh and, for t = 1, the film position.
  Rgb connect(const Context& c, const LightEmission& le, Vertex* light, Vertex* camera, int s, int t,
              PixelSampler& sampler, Vertex* sampled, Vec2* splat_at, RayCounters& counters);
  // The light passes' share of strategy (s, t)'s contribution (record_light): into the pixel's own `lp` (t >= 2), or
  // splatted where it lands, as the beauty's share is (t = 1).
  void record_strategy(Film& film, const Vertex* light, const Vertex* camera, const Vertex& sampled, int s, int t,
                       const Rgb& contribution, Vec2 splat_at, const AovWriter& aovs, LightPassSample& lp) const {
    const int k = s + t - 2;
    if (t >= 2) {
      if (k == 0) {
        (camera[1].kind == VertexKind::kLight && camera[1].infinite ? lp.background : lp.emission) += contribution;
      } else if (t >= 3) {
        record_light(lp, camera[1], Vec3(), Vec3(), false, k, contribution);
      } else {
        const Vertex& other = s == 1 ? sampled : light[s - 1];
        const Vec3 toward = other.infinite ? -other.dir : normalize(other.p - camera[1].p);
        record_light(lp, camera[1], toward, camera[1].wo, true, k, contribution);
      }
      return;
    }
    if (s < 2) return;  // light tracing's emitter seen by the lens: light tracing makes no light passes
    const int x = static_cast<int>(splat_at.x), y = static_cast<int>(splat_at.y);
    const PixelRegion& r = setup_.region;
    if (x < r.x || y < r.y || x >= r.x + r.width || y >= r.y + r.height) return;
    if (!is_finite(contribution) || contribution.x < 0 || contribution.y < 0 || contribution.z < 0) return;
    const Vertex& first = light[s - 1];
    LightPassSample one;
    record_light(one, first, first.wo, normalize(sampled.p - first.p), true, k, contribution * splat_scale_);
    aovs.add_light(film, x, y, one, true);
  }

  void splat(Film& film, Vec2 at, const Rgb& value) const {
    const int x = static_cast<int>(at.x), y = static_cast<int>(at.y);
    const PixelRegion& r = setup_.region;
    if (x < r.x || y < r.y || x >= r.x + r.width || y >= r.y + r.height) return;
    if (!is_finite(value) || value.x < 0 || value.y < 0 || value.z < 0) return;
    film.splat(x, y, value * splat_scale_);
  }

  bool light_only_;
  float splat_scale_ = 1;
  float disc_pdf_ = 1;
  std::vector<std::vector<Vertex>> vertices_;  // per worker
};

void BidirectionalIntegrator::render_tile(const PixelRegion& tile, int w, uint32_t first_sample, uint32_t count,
                                          Film& film, const AovWriter& aovs) {
  Worker& worker = this->worker(w);
  RayCounters counters;
  uint64_t nonfinite = 0;
  CameraAtTime at;  // a sample's time within the shutter, and the camera then
  std::vector<Vertex>& vertices = vertices_[static_cast<size_t>(w)];
  const size_t half = vertices.size() / 2;
  Vertex* camera = vertices.data();
  Vertex* light = vertices.data() + half;
  const PixelSampler::SeedKeys seed_keys(setup_.seed);
  const bool dispersive = setup_.scene->dispersive();
  for (int y = tile.y; y < tile.y + tile.height; ++y) {
    for (int x = tile.x; x < tile.x + tile.width; ++x) {
      const uint32_t pixel = static_cast<uint32_t>(y) * static_cast<uint32_t>(setup_.width) + static_cast<uint32_t>(x);
      for (uint32_t s = first_sample; s < first_sample + count; ++s) {
        PixelSampler sampler(seed_keys, pixel, s, setup_.sampler);
        camera_at_time(setup_, sampler, &at);
        MediumRng medium_rng(mix64(setup_.seed ^ mix64((static_cast<uint64_t>(pixel) << 32) | s)));
        const Context c{*setup_.scene, *at.camera, setup_.settings, disc_pdf_, at.time, &medium_rng};
        const Vec2 jitter = sampler.get2d();
        spectrum::WavelengthSample wavelength;
        if (dispersive) wavelength = spectrum::sample_wavelength(sampler.get1d_dimension0());
        SurfaceFeatures features;
        LightPassSample lp;
        Rgb l = sample(c, Vec2(static_cast<float>(x) + jitter.x, static_cast<float>(y) + jitter.y), sampler,
                       worker.arena, camera, light, film, counters, dispersive ? &wavelength : nullptr,
                       aovs.wants_features() ? &features : nullptr, aovs.wants_light() ? &lp : nullptr, aovs);
        if (light_only_) continue;
        if (!is_finite(l) || l.x < 0 || l.y < 0 || l.z < 0) {
          ++nonfinite;
          l = Rgb(0);
          lp = LightPassSample();  // dropped whole, as the beauty's sample is
        }
        film.add_sample_shared(x, y, l);
        if (!aovs.empty()) {
          // Only this thread adds this pixel's features; the light passes take splats from other threads too.
          aovs.add(film, x, y, s, features, l);
          if (aovs.wants_light()) aovs.add_light(film, x, y, lp, true);
        }
      }
    }
  }
  worker.rays += counters;
  worker.nonfinite += nonfinite;
}

Rgb BidirectionalIntegrator::sample(const Context& c, Vec2 film_pos, PixelSampler& sampler, ScratchArena& arena,
                                    Vertex* camera, Vertex* light, Film& film, RayCounters& counters,
                                    const spectrum::WavelengthSample* wavelength, SurfaceFeatures* features,
                                    LightPassSample* lp, const AovWriter& aovs) {
  arena.reset();
  const Scene& scene = c.scene;
  const int max_depth = c.settings.max_depth;
  const float wavelength_nm = wavelength ? wavelength->lambda_nm : 0.0f;
  const Vec2 u_lens = sampler.get2d();
  // The camera subpath (none for light tracing).
  int n_camera = 0;
  if (!light_only_) {
    Ray ray = c.camera.generate_ray(film_pos, u_lens);
    ray.time = c.time;
    ++counters.camera;
    camera[0] = Vertex();
    camera[0].kind = VertexKind::kCamera;
    camera[0].p = ray.origin;
    camera[0].beta = Rgb(1);
    float pdf_pos, pdf_dir;
    c.camera.importance_pdf(ray, &pdf_pos, &pdf_dir);
    n_camera = 1 + random_walk(c, ray, Rgb(1), pdf_dir, max_depth + 1, TransportMode::kRadiance, wavelength_nm, false,
                               sampler, arena, camera, counters);
    if (features) camera_features(camera, n_camera, features);
    if (lp && n_camera >= 2 && camera[1].kind == VertexKind::kSurface && camera[1].bsdf) {
      const Bsdf::LobeColors colors = camera[1].bsdf->lobe_colors();
      lp->color[0] += colors.diffuse;
      lp->color[1] += colors.glossy;
      lp->color[2] += colors.transmission;
    }
  }
  // The light subpath.
  int n_light = 0;
  const float u_select = sampler.get1d();
  const Vec2 u_pos = sampler.get2d(), u_dir = sampler.get2d();
  LightEmission le;
  if (scene.lights().sample_emission(u_select, u_pos, u_dir, &le)) {
    Vertex& l0 = light[0];
    l0 = Vertex();
    l0.kind = VertexKind::kLight;
    l0.p = le.ray.origin;
    l0.ng = le.infinite ? Vec3(0) : le.n;
    l0.light = le.light;
    l0.infinite = le.infinite;
    l0.dir = le.ray.dir;
    l0.delta_light = le.delta_pos || le.delta_dir;
    l0.beta = Rgb(1 / le.pdf_pos);  // the origin before a direction is chosen: for s = 1, t = 1
    l0.pdf_fwd = le.pdf_pos;
    Ray ray = le.ray;
    ray.time = c.time;
    ray.tmin = 0;
    ray.tmax = kInfinity;
    if (!le.infinite && !is_black(le.n)) ray.origin = offset_ray_origin(le.ray.origin, le.n, le.ray.dir);
    n_light = 1 + random_walk(c, ray, le.weight(), le.pdf_dir, max_depth, TransportMode::kImportance, wavelength_nm,
                              le.infinite, sampler, arena, light, counters);
    if (le.infinite) {
      // From infinity the first surface is found by area across the beam, and the light's own density is that of
      // its direction.
      if (n_light > 1) {
        light[1].pdf_fwd = c.disc_pdf;
        if (light[1].on_surface()) light[1].pdf_fwd *= std::abs(dot(light[1].ng, le.ray.dir));
      }
      l0.pdf_fwd = pdf_light_origin(c, l0, l0);
    }
  }
  // Every strategy.
  Rgb l(0);
  Vertex sampled;  // the vertex of s = 1 or t = 1, sampled afresh by connect
  const int t_max = light_only_ ? 1 : n_camera;
  for (int t = 1; t <= t_max; ++t) {
    for (int s = 0; s <= n_light; ++s) {
      // The path's scattering vertices: max_depth surfaces at most, and max_volume_depth in media.
      const int depth = s + t - 2;
      const int volume = (s >= 2 ? light[s - 1].volume : 0) + (t >= 2 ? camera[t - 1].volume : 0);
      if (depth < 0 || depth - volume > max_depth || volume > c.settings.max_volume_depth) continue;
      if (!light_only_ && s == 1 && t == 1) continue;  // the emitter seen directly: s = 0, t = 2 alone
      if (light_only_ && s == 0) continue;
      Vec2 splat_at;
      Rgb contribution = connect(c, le, light, camera, s, t, sampler, &sampled, &splat_at, counters);
      if (is_black(contribution)) continue;
      if (!light_only_) contribution *= mis_weight(c, light, camera, sampled, s, t);
      // The wavelength's weight, once, for a path that scatters at a dispersive vertex: decided by the path's
      // scattering vertices (camera[1..t-1] and light[1..s-1]; with s = 0, camera[t-1] is the emitter), the same
      // whichever strategy made the path, so that the strategies' weights still sum to 1.
      if (wavelength && ((s == 0 ? t >= 3 && camera[t - 2].dispersed : t >= 2 && camera[t - 1].dispersed) ||
                         (s >= 1 && light[s - 1].dispersed)))
        contribution *= wavelength->weight;
      if (t == 1)
        splat(film, splat_at, contribution);
      else
        l += contribution;
      if (lp) record_strategy(film, light, camera, sampled, s, t, contribution, splat_at, aovs, *lp);
    }
  }
  return l;
}

Rgb BidirectionalIntegrator::connect(const Context& c, const LightEmission& le, Vertex* light, Vertex* camera, int s,
                                     int t, PixelSampler& sampler, Vertex* sampled, Vec2* splat_at,
                                     RayCounters& counters) {
  const Scene& scene = c.scene;
  // A camera subpath that left the scene is joined to nothing but itself.
  if (t > 1 && s != 0 && camera[t - 1].kind == VertexKind::kLight) return Rgb(0);
  if (s == 0) {
    // The camera subpath found an emitter.
    const Vertex& pt = camera[t - 1];
    if (!pt.is_light()) return Rgb(0);
    const Vertex& prev = camera[t - 2];
    if (pt.infinite) {
      // Seen only through delta bounces (or directly): the environment as seen; otherwise the radiance light
      // sampling reads (one texel), as the path tracer does.
      bool seen = true;
      for (int i = 1; i < t - 1; ++i) seen = seen && camera[i].delta;
      float pdf_dir;
      const Rgb le = seen ? scene.environment.radiance(-pt.dir) : scene.environment.lighting(-pt.dir, &pdf_dir);
      return pt.beta * le;
    }
    return pt.beta * pt.material->emitted(pt.sp, normalize(prev.p - pt.p));
  }
  if (t == 1) {
    // Light tracing: the light subpath's vertex joined to a point sampled on the lens.
    Vertex& qs = light[s - 1];
    if (!qs.connectible() || qs.infinite) return Rgb(0);
    CameraImportanceSample cs;
    const Vec2 u_lens = sampler.get2d();
    if (!c.camera.sample_importance(qs.p, u_lens, &cs)) return Rgb(0);
    *sampled = Vertex();
    sampled->kind = VertexKind::kCamera;
    sampled->p = cs.p_lens;
    sampled->beta = Rgb(cs.importance / cs.pdf);
    Rgb l;
    if (qs.kind == VertexKind::kLight) {
      // The light's own point seen by the camera (light tracing's s = 1): its emission towards the lens.
      l = qs.beta * sampled->beta * le.emitted(cs.wi);
      if (qs.on_surface()) l *= std::abs(dot(cs.wi, qs.ng));
    } else {
      l = qs.beta * vertex_f(qs, cs.wi, TransportMode::kImportance) * sampled->beta * cos_at(qs, cs.wi);
    }
    if (is_black(l)) return Rgb(0);
    l *= transmittance(c, qs, *sampled, counters);
    *splat_at = cs.film;
    return l;
  }
  if (s == 1) {
    // Next-event estimation: the camera subpath's vertex joined to a point sampled on a light.
    Vertex& pt = camera[t - 1];
    if (!pt.connectible()) return Rgb(0);
    LightSample ls;
    const float u_select = sampler.get1d();
    const Vec2 u = sampler.get2d();
    if (!scene.lights().sample(pt.p, u_select, u, &ls) || !(ls.pdf > 0) || is_black(ls.radiance)) return Rgb(0);
    *sampled = Vertex();
    sampled->kind = VertexKind::kLight;
    sampled->light = ls.light;
    sampled->infinite = std::isinf(ls.dist);
    sampled->delta_light = ls.delta;
    if (sampled->infinite) {
      sampled->dir = -ls.wi;
    } else {
      sampled->p = ls.p_light;
      sampled->ng = ls.n_light;
    }
    sampled->beta = ls.radiance / ls.pdf;
    sampled->pdf_fwd = pdf_light_origin(c, *sampled, pt);
    const Rgb l = pt.beta * vertex_f(pt, ls.wi, TransportMode::kRadiance) * sampled->beta * cos_at(pt, ls.wi);
    if (is_black(l)) return Rgb(0);
    const Ray shadow = shadow_ray_to_light(pt.p, pt.ng, ls, c.time);
    const MediumTracker medium = MediumTracker::starting_in(medium_towards(c, pt, ls.wi), scene.medium.get());
    return l * shadow_transmittance(scene, shadow, medium, c.settings.max_volume_depth, *c.medium_rng, counters);
  }
  // Both subpaths' ends joined by a segment.
  Vertex& qs = light[s - 1];
  Vertex& pt = camera[t - 1];
  if (!qs.connectible() || !pt.connectible()) return Rgb(0);
  const Vec3 d = qs.p - pt.p;
  const float d2 = length_squared(d);
  if (!(d2 > 0)) return Rgb(0);
  const Vec3 w = d / std::sqrt(d2);  // from pt towards qs
  Rgb l = qs.beta * vertex_f(qs, -w, TransportMode::kImportance) * vertex_f(pt, w, TransportMode::kRadiance) * pt.beta;
  if (is_black(l)) return Rgb(0);
  l *= cos_at(qs, w) * cos_at(pt, w) / d2;
  return l * transmittance(c, pt, qs, counters);
}

}  // namespace

std::string integrator_camera_problem(const std::string& name, const Camera& camera) {
  if ((name == "light" || name == "bdpt") && !camera.has_importance())
    return "the " + name + " integrator needs a perspective camera";
  return {};
}

std::string integrator_aov_problem(const std::string& name, std::string_view aov) {
  const AovInfo* info = find_aov(aov);
  if (!info || (name != "light" && name != "bdpt") || info->source == AovSource::kSampleCount) return {};
  const std::string refusal = "the " + name + " integrator cannot make the pass \"" + std::string(aov) + "\"";
  if (info->source == AovSource::kLight && name == "light")
    return refusal + ": light tracing has no first bounce per pixel to sort its light by; use path or bdpt";
  if (info->source == AovSource::kSquares)
    return refusal + ": its pixels take splats of light paths started elsewhere, so their own samples do not measure " +
           "their variance; use path";
  if (name == "bdpt") return {};
  return refusal + ": light tracing has no first surface per pixel; use path or bdpt";
}

std::string integrator_adaptive_problem(const std::string& name) {
  if (name != "light" && name != "bdpt") return {};
  return "the " + name + " integrator cannot sample adaptively: its light paths splat onto every pixel, so a " +
         "pixel's own samples do not measure its error; use path";
}

double sample_work(const IntegratorSettings& settings, bool scattering, std::string* formula) {
  const double events = std::max(1, settings.max_depth) + (scattering ? settings.max_volume_depth : 0);
  const bool pairs = settings.name == "bdpt";
  *formula = std::string(scattering ? "(max_depth + max_volume_depth)" : "max_depth") + (pairs ? "^2" : "");
  return pairs ? events * events : events;
}

void register_bidirectional(IntegratorRegistry& registry) {
  registry.add("light",
               [](const IntegratorSetup& setup) { return std::make_unique<BidirectionalIntegrator>(setup, true); });
  registry.add("bdpt",
               [](const IntegratorSetup& setup) { return std::make_unique<BidirectionalIntegrator>(setup, false); });
}

}  // namespace tessera
