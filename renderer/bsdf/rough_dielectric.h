// A rough dielectric interface (Walter et al. 2007, "Microfacet Models for Refraction through Rough Surfaces"): the
// reflection and refraction of one microfacet lobe, shared by the dielectric model and by gltf_pbr's solid
// (KHR_materials_volume) transmission.
//
// Reflection by eq. 20 and transmission by eq. 21, with Walter's i = wi, o = wo and eta_i, eta_o the indices on
// their sides,
//   f_t = |wi.m| |wo.m| / (|wi.n| |wo.n|) * eta_o^2 (1 - F) G D / (eta_i (wi.m) + eta_o (wo.m))^2,
// which is the radiance form (a 1/eta'^2, eta' = eta_(wi side) / eta_(wo side), Veach 1997, 5.2); m is the
// generalised half vector ~ eta_i wi + eta_o wo (eq. 16). Sampling draws a visible normal of wo (microfacet.h),
// chooses reflection or refraction in proportion to F(wo.m) w_r and (1 - F(wo.m)) w_t, and converts by the
// Jacobians 1/(4 |wo.m|) (eq. 14) and eta_i^2 |wi.m| / (eta_i wi.m + eta_o wo.m)^2 (eq. 17).
//
// Local frame: +z points outside; eta is eta_inside / eta_outside (not 1).
#pragma once

#include "renderer/bsdf/microfacet.h"

namespace tessera {

struct RoughDielectric {
  MicrofacetDistribution dist;
  float eta = 1.5f;
  // Weights of the reflected and the transmitted part (the largest channel of their colours), for choosing between
  // them when sampling.
  float weight_r = 1, weight_t = 1;

  // The generalised half vector of (wo, wi) on the upper side (eq. 16), with eta' = eta_(wi side) / eta_(wo side)
  // (1 for reflection); false for degenerate or back-facing configurations.
  bool half_vector(const Vec3& wo, const Vec3& wi, Vec3* wm, float* etap) const;
  // f(wo, wi) without colour (eq. 20 or 21, radiance form); *transmitted says which.
  float eval(const Vec3& wo, const Vec3& wi, bool* transmitted) const;
  // The density with which `sample` picks wi.
  float pdf(const Vec3& wo, const Vec3& wi) const;
  // Samples wi; returns false when the sample is lost (a direction on the wrong side, nothing to choose).
  // *transmitted says which part was sampled, *etap the eta' crossed (1 for reflection).
  bool sample(const Vec3& wo, float uc, Vec2 u, Vec3* wi, bool* transmitted, float* etap) const;
};

}  // namespace tessera
