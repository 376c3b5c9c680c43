#include "renderer/bsdf/fresnel.h"

#include "renderer/spectrum.h"

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

namespace {

// The m-th interference term of the Airy sum integrated against the CIE 1931 colour matching functions, for an
// optical path difference `opd_nm` and a phase shift `shift` per channel (Belcour & Barla 2017, eq. 10 and their
// supplementary Gaussian fit of x, y, z in Fourier space; normalised by the integral of y), in linear sRGB.
Rgb thin_film_sensitivity(double opd_nm, const Rgb& shift) {
  const double phase = 2 * kPi * opd_nm * 1e-9;
  // Amplitude, mean and variance of each Gaussian (x has a second lobe).
  const double amp[3] = {5.4856e-13, 4.4201e-13, 5.2481e-13};
  const double mean[3] = {1.6810e+06, 1.7953e+06, 2.2084e+06};
  const double var[3] = {4.3278e+09, 9.3046e+09, 6.6121e+09};
  double xyz[3];
  for (int i = 0; i < 3; ++i)
    xyz[i] =
        amp[i] * std::sqrt(2 * kPi * var[i]) * std::cos(mean[i] * phase + shift[i]) * std::exp(-phase * phase * var[i]);
  xyz[0] += 9.7470e-14 * std::sqrt(2 * kPi * 4.5282e+09) * std::cos(2.2399e+06 * phase + shift[0]) *
            std::exp(-4.5282e+09 * phase * phase);
  for (double& v : xyz) v /= 1.0685e-7;
  return spectrum::xyz_to_linear_srgb(xyz[0], xyz[1], xyz[2]);
}

}  // namespace

Rgb fresnel_thin_film(float cos_theta, float outside_ior, float film_ior, float thickness_nm, const Rgb& base_f0) {
  const float c1 = clamp(std::abs(cos_theta), 0.0f, 1.0f);
  // The film's index, smoothly to the outside's as the thickness goes to 0 (smoothstep over 0..0.03 nm).
  const float s = clamp(thickness_nm / 0.03f, 0.0f, 1.0f);
  const float n2 = outside_ior + (film_ior - outside_ior) * (s * s * (3 - 2 * s));
  // Snell's law into the film; total internal reflection at the first interface reflects everything.
  const float sin2_sq = sqr(outside_ior / n2) * (1 - c1 * c1);
  if (sin2_sq >= 1) return Rgb(1);
  const float c2 = std::sqrt(1 - sin2_sq);
  // First interface (outside to film): the exact dielectric Fresnel, as Belcour & Barla's own implementation has it
  // (the glTF appendix's Schlick form reflects (1 - cos)^5 at grazing angles even where the film's index equals the
  // outside's); phase shift pi on reflection off a denser medium.
  const float r12 = fresnel_dielectric(c1, n2 / outside_ior);
  const float t121 = 1 - r12;
  const float phi21 = n2 < outside_ior ? 0.0f : kPi;  // pi - phi12
  // Second interface (film to base): the base's index from its f0 against air, then its f0 against the film.
  Rgb r23, phase;
  for (int i = 0; i < 3; ++i) {
    const float sq = std::sqrt(clamp(base_f0[i], 0.0f, 0.9999f));
    const float n3 = (1 + sq) / (1 - sq);
    r23[i] = fresnel_schlick(sqr((n3 - n2) / (n3 + n2)), c2);
    phase[i] = phi21 + (n3 < n2 ? kPi : 0.0f);
  }
  // The Airy sum: R = R12 + T121^2 R23 / (1 - R12 R23) + sum_m C_m S_m (Belcour & Barla 2017, eqs. 6-9), with
  // C_m = (Rs - T121) r123^m, of which the first two interference terms are kept.
  Rgb result, cm, r123;
  for (int i = 0; i < 3; ++i) {
    const float r123_sq = std::min(r12 * r23[i], 0.9999f);
    r123[i] = std::sqrt(r123_sq);
    const float rs = t121 * t121 * r23[i] / (1 - r123_sq);
    result[i] = r12 + rs;
    cm[i] = rs - t121;
  }
  if (r12 > 0) {  // without a first interface there is no interference
    const double opd = 2.0 * n2 * thickness_nm * c2;
    for (int m = 1; m <= 2; ++m) {
      cm = cm * r123;
      const Rgb sm = thin_film_sensitivity(m * opd, phase * static_cast<float>(m));
      result = result + cm * sm * 2.0f;
    }
  }
  for (int i = 0; i < 3; ++i) result[i] = clamp(result[i], 0.0f, 1.0f);
  return result;
}

}  // namespace tessera
