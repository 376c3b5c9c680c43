// Fresnel reflectance and the laws of reflection and refraction (Dutré, Bala & Bekaert, Advanced Global
// Illumination, 2nd ed., §2.5.3 "Specular Refraction" and "Fresnel Equations"; Pharr, Jakob & Humphreys, Physically
// Based Rendering, 3rd ed., §8.2.1 "Fresnel Reflectance").
#pragma once

#include "renderer/math.h"

namespace tessera {

// Unpolarised reflectance of a smooth dielectric interface, F = (R_s + R_p) / 2 (Pharr et al., §8.2.1).
// `cos_theta_i` is the cosine of the incident angle measured on the side the light comes from (its sign tells the
// side: > 0 outside, < 0 inside), `eta` = eta_inside / eta_outside. Returns 1 under total internal reflection.
float fresnel_dielectric(float cos_theta_i, float eta);

// The two polarised reflectances of the same interface (for tests and teaching): R_s (perpendicular), R_p
// (parallel).
void fresnel_dielectric_polarized(float cos_theta_i, float eta, float* r_s, float* r_p);

// Reflectance of a conductor with complex index eta + i k (relative to the outside medium), per RGB channel, from
// the Fresnel equations with a complex index of refraction (Born & Wolf, Principles of Optics, 14.2), evaluated in
// real arithmetic (the a^2 + b^2 form of the complex cos of the transmitted angle).
Rgb fresnel_conductor(float cos_theta_i, const Rgb& eta, const Rgb& k);

// Schlick's approximation F = F0 + (F90 - F0)(1 - cos)^5 (Schlick 1994, eq. 24; glTF 2.0 appendix B).
inline Rgb fresnel_schlick(const Rgb& f0, const Rgb& f90, float cos_theta) {
  float m = clamp(1 - std::abs(cos_theta), 0.0f, 1.0f);
  float m2 = m * m;
  return f0 + (f90 - f0) * (m2 * m2 * m);
}
inline float fresnel_schlick(float f0, float cos_theta) {
  float m = clamp(1 - std::abs(cos_theta), 0.0f, 1.0f);
  float m2 = m * m;
  return f0 + (1 - f0) * (m2 * m2 * m);
}

// Reflectance of a base (its normal-incidence reflectance `base_f0`, per channel, seen from air) under a thin
// dielectric film of index `film_ior` and thickness `thickness_nm` nanometres, in an outside medium of index
// `outside_ior`, at incidence cosine `cos_theta` (Belcour & Barla 2017, "A Practical Extension to Microfacet Theory
// for the Modeling of Varying Iridescence", sections 3-4, as the glTF KHR_materials_iridescence specification's
// appendix evaluates it): the Airy sum of the film's inter-reflections, the exact Fresnel at the film's surface and
// Schlick's approximation at the base, its interference terms integrated against the colour matching functions by
// their Gaussian fit in Fourier space, then XYZ to linear sRGB. The film's index goes smoothly to the outside one as
// the thickness goes to 0, so at thickness 0, or with a film of the outside medium's index, the result is
// Schlick(base_f0, 1, cos_theta). Clamped to [0, 1] (the fit can leave the sRGB gamut).
Rgb fresnel_thin_film(float cos_theta, float outside_ior, float film_ior, float thickness_nm, const Rgb& base_f0);

// Normal-incidence reflectance of a dielectric: ((eta1 - eta2) / (eta1 + eta2))^2.
inline float f0_from_ior(float ior) {
  return sqr((ior - 1) / (ior + 1));
}

// Mirror reflection about the normal +z of the local frame: R = 2 (N.Psi) N - Psi (Dutré et al., §2.5.3).
inline Vec3 reflect_local(const Vec3& w) {
  return {-w.x, -w.y, w.z};
}

// Refraction of `wi` (pointing away from the surface) through a surface with normal `n` on wi's side, with
// relative index `eta` = eta_t / eta_i (Snell: eta_i sin(theta_i) = eta_t sin(theta_t), Dutré et al., §2.5.3, eq. for
// T). Returns false under total internal reflection.
bool refract(const Vec3& wi, const Vec3& n, float eta, Vec3* wt);

// Hemispherical average of the dielectric Fresnel reflectance, 2 \int_0^1 F(mu) mu dmu, by numerical quadrature
// (the "diffuse Fresnel reflectance" of d'Eon and Irving 2011, used by the plastic model). `eta` as above; pass
// 1/eta for light hitting the interface from inside.
float fresnel_diffuse_reflectance(float eta);

}  // namespace tessera
