// The BSDF interface: the BRDF f_r(x, Psi -> Theta) of Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed.,
// §2.5, extended to transmission.
//
// Conventions, shared by every model:
// - Directions are unit vectors in the local shading frame: +z is the shading normal of the surface as modelled
//   (the side the mesh's winding or the sphere's outward normal points to). `wo` points towards the viewer (where
//   the path came from), `wi` towards the light. Both may lie on either side.
// - `eval` returns f(wo, wi) alone, without the cosine factor; the integrator multiplies by |cos theta_i|.
// - Opaque reflectors reflect on both sides of a surface: a back-side `wo` is treated like a front-side one
//   mirrored through the surface (the pbrt convention), so a closed object seen from inside is lit like from outside.
// - `sample` returns the sampled direction, f and the solid-angle pdf. For a delta (specular) lobe, pdf is the
//   discrete probability of choosing that lobe and f is the lobe's weight divided by |cos theta_i|, so that
//   f |cos| / pdf is the path weight; `eval` and `pdf` return 0 for delta lobes.
// - `eta` of a sample is the relative index of refraction crossed (1 for reflection), for radiance scaling.
// - eval and sample give the BSDF radiance transport uses (paths from the camera). Paths from the lights carry
//   importance and use the adjoint BSDF f*(wo, wi) = f(wi, wo) (Veach 1997, 3.7.6 and 5.2), `wo` still pointing to
//   where the path came from: eval_for and sample_for with TransportMode::kImportance. The two differ only across
//   refraction, where the radiance form's 1/eta'^2 is not there (Veach 1997, 5.2: radiance is compressed into the
//   denser medium, importance is not); models that refract override eval_adjoint and sample_adjoint. The correction
//   of shading normals (Veach 1997, 5.3) depends on the geometric normal and is the integrator's.
#pragma once

#include <cstdint>
#include <optional>

#include "renderer/math.h"

namespace tessera {

enum BsdfFlags : uint32_t {
  kBsdfNone = 0,
  kBsdfReflection = 1u << 0,
  kBsdfTransmission = 1u << 1,
  kBsdfDiffuse = 1u << 2,
  kBsdfGlossy = 1u << 3,
  kBsdfSpecular = 1u << 4,  // a Dirac delta lobe
  kBsdfOneLobe = 1u << 5,   // sample() ignores its lobe choice `uc` (the integrator then does not compute one)
};

inline bool is_delta(uint32_t flags) {
  return (flags & kBsdfSpecular) != 0;
}
inline bool has_non_delta(uint32_t flags) {
  return (flags & (kBsdfDiffuse | kBsdfGlossy)) != 0;
}

// What a path carries (Veach 1997, 3.7.6): radiance, traced from the camera; or importance, traced from the lights.
enum class TransportMode { kRadiance, kImportance };

struct BsdfSample {
  Rgb f;
  Vec3 wi;
  float pdf = 0;
  uint32_t flags = 0;  // the lobe that was sampled
  float eta = 1;
};

class Bsdf {
 public:
  virtual Rgb eval(const Vec3& wo, const Vec3& wi) const = 0;
  // `uc` chooses a lobe, `u` samples within it; both uniform in [0,1).
  virtual std::optional<BsdfSample> sample(const Vec3& wo, float uc, Vec2 u) const = 0;
  virtual float pdf(const Vec3& wo, const Vec3& wi) const = 0;
  // eval and pdf of the same pair at once; models that share work between the two override it.
  virtual Rgb eval_pdf(const Vec3& wo, const Vec3& wi, float* pdf_out) const {
    *pdf_out = pdf(wo, wi);
    return eval(wo, wi);
  }
  // The adjoint BSDF (see the conventions above); the same as eval and sample for models that do not refract.
  virtual Rgb eval_adjoint(const Vec3& wo, const Vec3& wi) const { return eval(wo, wi); }
  virtual std::optional<BsdfSample> sample_adjoint(const Vec3& wo, float uc, Vec2 u) const { return sample(wo, uc, u); }
  Rgb eval_for(TransportMode mode, const Vec3& wo, const Vec3& wi) const {
    return mode == TransportMode::kRadiance ? eval(wo, wi) : eval_adjoint(wo, wi);
  }
  std::optional<BsdfSample> sample_for(TransportMode mode, const Vec3& wo, float uc, Vec2 u) const {
    return mode == TransportMode::kRadiance ? sample(wo, uc, u) : sample_adjoint(wo, uc, u);
  }
  // Union of the lobes this BSDF has.
  virtual uint32_t flags() const = 0;
  // Albedo-like colour for the first-hit albedo AOV and for Russian roulette heuristics.
  virtual Rgb albedo_hint() const { return Rgb(0.5f); }
  // The perceptual roughness of the main lobe, for the roughness pass: sqrt(alpha) of a microfacet lobe (glTF's
  // roughness, whose square is alpha), 0 for a perfectly smooth mirror or glass, 1 for a diffuse surface.
  virtual float roughness_hint() const { return 1; }

  // The light passes (aov.h) sort light by the lobe that scattered it at the path's first bounce, as Blender Cycles
  // sorts its passes: diffuse (diffuse reflection and diffuse transmission), glossy (every other reflection, sheen
  // and clearcoat among them) and transmission (every other refraction).
  // The diffuse lobes' share of eval(wo, wi); the rest of eval is glossy where wi is on wo's side, transmission
  // where it is not. A model with diffuse lobes beside others says which part is theirs; one of diffuse lobes only
  // is all diffuse, one without any has none.
  virtual Rgb eval_diffuse(const Vec3& wo, const Vec3& wi) const {
    return (flags() & kBsdfDiffuse) && !(flags() & (kBsdfGlossy | kBsdfSpecular)) ? eval(wo, wi) : Rgb(0);
  }
  // The colour of each lobe class (the light passes' diffuse_color, glossy_color, transmission_color): what the
  // class's lobes tint the light they scatter by. A model of one class gives its albedo_hint to that class.
  struct LobeColors {
    Rgb diffuse, glossy, transmission;
  };
  virtual LobeColors lobe_colors() const {
    const uint32_t f = flags();
    LobeColors c;
    if (f & kBsdfDiffuse)
      c.diffuse = albedo_hint();
    else if (f & kBsdfTransmission)
      c.transmission = albedo_hint();
    else if (f & (kBsdfGlossy | kBsdfSpecular))
      c.glossy = albedo_hint();
    return c;
  }

 protected:
  ~Bsdf() = default;  // BSDFs live in a ScratchArena and are never destroyed through a base pointer.
};

// The lobe class (Bsdf::lobe_colors) of a sampled lobe's flags: 0 diffuse, 1 glossy, 2 transmission.
inline int lobe_class(uint32_t sampled) {
  if (sampled & kBsdfDiffuse) return 0;
  return (sampled & kBsdfTransmission) ? 2 : 1;
}

inline float cos_theta(const Vec3& w) {
  return w.z;
}
inline float abs_cos_theta(const Vec3& w) {
  return std::abs(w.z);
}
inline bool same_hemisphere(const Vec3& a, const Vec3& b) {
  return a.z * b.z > 0;
}

}  // namespace tessera
