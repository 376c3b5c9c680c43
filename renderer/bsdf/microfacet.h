// Microfacet distributions for rough reflection and transmission: Beckmann (Cook & Torrance 1982; Dutré, Bala &
// Bekaert, Advanced Global Illumination, 2nd ed., §2.5.4 "Cook-Torrance model") and GGX / Trowbridge-Reitz (Walter et
// al. 2007), isotropic or anisotropic along the shading frame's tangent (+x of the local frame), with Smith masking
// (Heitz 2014, "Understanding the Masking-Shadowing Function") or the V-cavity term (Cook & Torrance 1982), and
// sampling of the visible normals (Heitz & d'Eon 2014; Heitz 2018, "Sampling the GGX Distribution of Visible Normals").
//
// Normalisation: D integrates to one over the projected solid angle, \int D(m) cos(theta_m) dm = 1 (Walter 2007,
// eq. 4). Dutré et al.'s Beckmann D(theta_h) = exp(-(tan/m)^2) / (m^2 cos^4) lacks the 1/pi of that normalisation;
// their Cook-Torrance expression F/pi * D G / ((N.Psi)(N.Theta)) carries the 1/pi outside D instead and uses 1 where
// the derivation from the half-vector Jacobian gives 1/4 (Walter 2007, eq. 20). tessera uses
//   f = D G F / (4 |cos theta_i| |cos theta_o|).
#pragma once

#include "renderer/math.h"

namespace tessera {

enum class MicrofacetType : uint8_t { kBeckmann, kGgx };
enum class MaskingType : uint8_t { kSmith, kVCavity };

struct MicrofacetDistribution {
  MicrofacetType type = MicrofacetType::kGgx;
  MaskingType masking = MaskingType::kSmith;
  float alpha_x = 0.1f;  // roughness along the tangent (local +x)
  float alpha_y = 0.1f;  // roughness along the bitangent (local +y)

  // Below this roughness the surface is treated as smooth (a delta lobe), as pbrt-v4 does.
  bool effectively_smooth() const { return std::max(alpha_x, alpha_y) < 1e-3f; }
  // The perceptual roughness sqrt(alpha), alpha the geometric mean of the two, at most 1 (Bsdf::roughness_hint).
  float roughness() const { return std::min(1.0f, std::sqrt(std::sqrt(alpha_x * alpha_y))); }

  // D(m): the distribution of normals (m in the upper hemisphere).
  float d(const Vec3& m) const;
  // Smith's Lambda(w) (Heitz 2014, eq. 72 Beckmann, eq. 86 GGX), anisotropic through the projected roughness.
  float lambda(const Vec3& w) const;
  // Masking of direction w by the microsurface seen around normal m.
  float g1(const Vec3& w, const Vec3& m) const;
  // Masking-shadowing of the pair (wo, wi) around m: height-correlated Smith, 1 / (1 + Lambda(o) + Lambda(i))
  // (Heitz 2014, eq. 99), or Cook & Torrance's V-cavity min(1, 2 (N.H)(N.Theta)/(Theta.H), 2 (N.H)(N.Psi)/(Theta.H)).
  float g(const Vec3& wo, const Vec3& wi, const Vec3& m) const;

  // Density of the normals visible from w, D_w(m) = G1(w, m) max(0, w.m) D(m) / |cos theta_w| (Heitz 2014,
  // eq. 38); w may lie on either side, m is taken on w's side.
  float d_visible(const Vec3& w, const Vec3& m) const;
  // Samples m from D_w(m) for w in the upper hemisphere. `u_extra` is only used by the V-cavity.
  Vec3 sample_visible(const Vec3& w, Vec2 u, float u_extra) const;
  // Samples m from D(m) cos(theta_m).
  Vec3 sample_normal(Vec2 u) const;
};

// Half vector of a reflection pair, on the upper side; false when degenerate.
inline bool reflection_half_vector(const Vec3& wo, const Vec3& wi, Vec3* h) {
  Vec3 s = wo + wi;
  float len2 = length_squared(s);
  if (!(len2 > 0)) return false;
  *h = s / std::sqrt(len2);
  if (h->z < 0) *h = -*h;
  return true;
}

// The microfacet reflection lobe without Fresnel: eval D G / (4 cos_o cos_i), sampled by visible normals.
// wo and wi in the upper hemisphere (callers mirror back-side directions first).
float microfacet_reflection_eval(const MicrofacetDistribution& dist, const Vec3& wo, const Vec3& wi);
float microfacet_reflection_pdf(const MicrofacetDistribution& dist, const Vec3& wo, const Vec3& wi);
// Both of the above for a pair whose half vector `h` (reflection_half_vector) the caller has: eval returned, the pdf
// of sampling wi stored in *pdf. One evaluation of D and of each Lambda.
float microfacet_reflection_eval_pdf(const MicrofacetDistribution& dist, const Vec3& wo, const Vec3& wi, const Vec3& h,
                                     float* pdf);
// Samples wi; returns false when the sampled direction leaves the upper hemisphere.
bool microfacet_reflection_sample(const MicrofacetDistribution& dist, const Vec3& wo, Vec2 u, float u_extra, Vec3* wi);

}  // namespace tessera
