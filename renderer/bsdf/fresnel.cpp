#include "renderer/bsdf/fresnel.h"

namespace tessera {

void fresnel_dielectric_polarized(float cos_theta_i, float eta, float* r_s, float* r_p) {
  // Light arriving from inside: swap the media.
  if (cos_theta_i < 0) {
    eta = 1 / eta;
    cos_theta_i = -cos_theta_i;
  }
  cos_theta_i = std::min(cos_theta_i, 1.0f);
  // Snell's law for the transmitted angle (Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed., §2.5.3).
  float sin2_theta_i = 1 - cos_theta_i * cos_theta_i;
  float sin2_theta_t = sin2_theta_i / (eta * eta);
  if (sin2_theta_t >= 1) {  // total internal reflection
    *r_s = *r_p = 1;
    return;
  }
  float cos_theta_t = safe_sqrt(1 - sin2_theta_t);
  // The Fresnel equations (Dutré et al., §2.5.3; Pharr, Jakob & Humphreys, PBR 3rd ed., §8.2.1), n1 = 1, n2 = eta:
  //   R_s = |(n1 cos_i - n2 cos_t) / (n1 cos_i + n2 cos_t)|^2,
  //   R_p = |(n1 cos_t - n2 cos_i) / (n1 cos_t + n2 cos_i)|^2.
  float rs = (cos_theta_i - eta * cos_theta_t) / (cos_theta_i + eta * cos_theta_t);
  float rp = (cos_theta_t - eta * cos_theta_i) / (cos_theta_t + eta * cos_theta_i);
  *r_s = rs * rs;
  *r_p = rp * rp;
}

float fresnel_dielectric(float cos_theta_i, float eta) {
  float rs, rp;
  fresnel_dielectric_polarized(cos_theta_i, eta, &rs, &rp);
  return 0.5f * (rs + rp);
}

Rgb fresnel_conductor(float cos_theta_i, const Rgb& eta, const Rgb& k) {
  // The complex Fresnel equations in real arithmetic: with n^2 - sin^2 theta_i = (a + i b)^2,
  //   a^2 + b^2 = sqrt((eta^2 - k^2 - sin^2)^2 + 4 eta^2 k^2),  a^2 = (a^2 + b^2 + eta^2 - k^2 - sin^2) / 2,
  //   R_s = (a^2 + b^2 + cos^2 - 2 a cos) / (a^2 + b^2 + cos^2 + 2 a cos),
  //   R_p = R_s (cos^2 (a^2 + b^2) + sin^4 - 2 a cos sin^2) / (cos^2 (a^2 + b^2) + sin^4 + 2 a cos sin^2),
  // equal to the complex form (tested against it) without a complex square root per channel.
  const float cos_i = clamp(std::abs(cos_theta_i), 0.0f, 1.0f);
  const float cos2 = cos_i * cos_i, sin2 = 1 - cos2, sin4 = sin2 * sin2;
  Rgb out;
  for (int c = 0; c < 3; ++c) {
    const float eta2 = eta[c] * eta[c], k2 = k[c] * k[c];
    const float t0 = eta2 - k2 - sin2;
    const float a2b2 = std::sqrt(t0 * t0 + 4 * eta2 * k2);
    // a^2 = (a^2 + b^2 + t0) / 2, in the form without cancellation when t0 < 0 (an index below 1 with little k).
    const float a = std::sqrt(t0 >= 0 ? 0.5f * (a2b2 + t0) : (a2b2 - t0 > 0 ? 2 * eta2 * k2 / (a2b2 - t0) : 0.0f));
    const float t1 = a2b2 + cos2, t2 = 2 * a * cos_i;
    const float rs = t1 + t2 > 0 ? (t1 - t2) / (t1 + t2) : 1.0f;
    const float t3 = cos2 * a2b2 + sin4, t4 = t2 * sin2;
    const float rp = t3 + t4 > 0 ? rs * (t3 - t4) / (t3 + t4) : rs;
    out[c] = clamp(0.5f * (rs + rp), 0.0f, 1.0f);
  }
  return out;
}

bool refract(const Vec3& wi, const Vec3& n, float eta, Vec3* wt) {
  // Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed., §2.5.3:
  //   T = -(eta_1/eta_2) Psi + N ((eta_1/eta_2)(N.Psi) - sqrt(1 - (eta_1/eta_2)^2 (1 - (N.Psi)^2))).
  float cos_i = dot(n, wi);
  float r = 1 / eta;
  float sin2_t = r * r * std::max(0.0f, 1 - cos_i * cos_i);
  if (sin2_t >= 1) return false;
  float cos_t = std::sqrt(1 - sin2_t);
  *wt = -wi * r + n * (r * cos_i - cos_t);
  return true;
}

float fresnel_diffuse_reflectance(float eta) {
  // 2 \int_0^1 F(mu) mu dmu by the composite Simpson rule; the integrand is smooth except at the critical angle,
  // which a fine grid handles to well below 1e-4.
  const int n = 2048;
  double sum = 0;
  for (int i = 0; i <= n; ++i) {
    double mu = static_cast<double>(i) / n;
    double w = (i == 0 || i == n) ? 1 : (i % 2 ? 4 : 2);
    sum += w * fresnel_dielectric(static_cast<float>(mu), eta) * mu;
  }
  return static_cast<float>(2 * sum / (3.0 * n));
}

}  // namespace tessera
