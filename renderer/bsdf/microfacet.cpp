#include "renderer/bsdf/microfacet.h"

#include <cmath>

namespace tessera {

namespace {

constexpr double kSqrtPi = 1.7724538509055160273;

// Squared tangent of w "stretched" by the roughness: (alpha_x^2 x^2 + alpha_y^2 y^2) / z^2 = alpha_w^2 tan^2.
float stretched_tan2(const MicrofacetDistribution& d, const Vec3& w) {
  return (sqr(d.alpha_x * w.x) + sqr(d.alpha_y * w.y)) / (w.z * w.z);
}

// Solves CDF(x) = u for the standard Beckmann visible-slope marginal along the incidence plane,
//   p(x) ~ (1 - x tan(theta)) exp(-x^2) for x < cot(theta)        (Heitz & d'Eon 2014, section 5.2 / appendix),
//   CDF(x) ~ sqrt(pi)/2 (1 + erf x) + tan(theta)/2 exp(-x^2),
// by Newton's method safeguarded with bisection, in double precision. tan_theta = 0 gives the Gaussian
// exp(-x^2)/sqrt(pi), used for the other slope.
double solve_beckmann_slope(double u, double tan_theta) {
  double hi = tan_theta > 1e-8 ? std::min(1 / tan_theta, 8.0) : 8.0;
  double lo = -8.0;
  auto cdf = [&](double x) { return 0.5 * kSqrtPi * (1 + std::erf(x)) + 0.5 * tan_theta * std::exp(-x * x); };
  const double c_lo = cdf(lo), c_hi = cdf(hi);
  const double target = c_lo + u * (c_hi - c_lo);
  double x = 0.5 * (lo + hi);
  if (tan_theta <= 1e-8) x = 0;
  for (int it = 0; it < 64; ++it) {
    double value = cdf(x) - target;
    if (value > 0)
      hi = x;
    else
      lo = x;
    if (std::abs(value) < 1e-12) break;
    double density = (1 - x * tan_theta) * std::exp(-x * x);
    double next = density > 1e-300 ? x - value / density : 0.5 * (lo + hi);
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (std::abs(next - x) < 1e-12) {
      x = next;
      break;
    }
    x = next;
  }
  return x;
}

// Beckmann visible normal, Heitz & d'Eon 2014 (section 5): stretch w to the unit-roughness configuration, sample
// the visible slopes there, rotate and unstretch.
Vec3 sample_beckmann_visible(const MicrofacetDistribution& d, const Vec3& w, Vec2 u) {
  Vec3 ws = normalize(Vec3(d.alpha_x * w.x, d.alpha_y * w.y, w.z));
  float sin_theta = std::sqrt(std::max(0.0f, ws.x * ws.x + ws.y * ws.y));
  float cos_phi = 1, sin_phi = 0;
  if (sin_theta > 1e-7f) {
    cos_phi = ws.x / sin_theta;
    sin_phi = ws.y / sin_theta;
  }
  double tan_theta = ws.z > 0 ? sin_theta / ws.z : 1e8;
  // Keep u off 0 and 1: the slope distribution has infinite tails, and a float u of exactly 0 would otherwise map
  // to the end of the search interval (a slope of 8 alphas, far beyond where 1e-6 of the mass lies).
  double sx = solve_beckmann_slope(clamp<double>(u.x, 1e-6, 1 - 1e-6), tan_theta);
  double sy = solve_beckmann_slope(clamp<double>(u.y, 1e-6, 1 - 1e-6), 0.0);
  double x = cos_phi * sx - sin_phi * sy;
  double y = sin_phi * sx + cos_phi * sy;
  x *= d.alpha_x;
  y *= d.alpha_y;
  return normalize(Vec3(static_cast<float>(-x), static_cast<float>(-y), 1.0f));
}

// GGX visible normal, Heitz 2018 ("Sampling the GGX Distribution of Visible Normals", JCGT 7(4), listing 1):
// a uniform point on the projected hemisphere of the stretched configuration.
Vec3 sample_ggx_visible(const MicrofacetDistribution& d, const Vec3& w, Vec2 u) {
  Vec3 vh = normalize(Vec3(d.alpha_x * w.x, d.alpha_y * w.y, w.z));
  float len2 = vh.x * vh.x + vh.y * vh.y;
  Vec3 t1 = len2 > 0 ? Vec3(-vh.y, vh.x, 0) / std::sqrt(len2) : Vec3(1, 0, 0);
  Vec3 t2 = cross(vh, t1);
  float r = std::sqrt(u.x);
  float phi = 2 * kPi * u.y;
  float p1 = r * std::cos(phi);
  float p2 = r * std::sin(phi);
  float s = 0.5f * (1 + vh.z);
  p2 = (1 - s) * std::sqrt(std::max(0.0f, 1 - p1 * p1)) + s * p2;
  Vec3 nh = t1 * p1 + t2 * p2 + vh * std::sqrt(std::max(0.0f, 1 - p1 * p1 - p2 * p2));
  return normalize(Vec3(d.alpha_x * nh.x, d.alpha_y * nh.y, std::max(1e-7f, nh.z)));
}

float vcavity_g1(const Vec3& w, const Vec3& m) {
  float wm = dot(w, m);
  if (wm * w.z <= 0) return 0;
  return std::min(1.0f, 2 * std::abs(m.z * w.z / wm));
}

}  // namespace

float MicrofacetDistribution::d(const Vec3& m) const {
  if (m.z <= 0) return 0;
  float cos2 = m.z * m.z;
  float e = (sqr(m.x / alpha_x) + sqr(m.y / alpha_y)) / cos2;
  float norm = kPi * alpha_x * alpha_y * cos2 * cos2;
  if (type == MicrofacetType::kBeckmann) {
    // Beckmann, anisotropic (Walter 2007, eq. 25; Heitz 2014, eq. 71): exp(-tan^2 (cos^2/ax^2 + sin^2/ay^2)) /
    // (pi ax ay cos^4).
    return std::exp(-e) / norm;
  }
  // GGX / Trowbridge-Reitz, anisotropic (Heitz 2014, eq. 85): 1 / (pi ax ay cos^4 (1 + tan^2 (...))^2).
  return 1 / (norm * sqr(1 + e));
}

float MicrofacetDistribution::lambda(const Vec3& w) const {
  if (w.z == 0) return kInfinity;
  float t2 = stretched_tan2(*this, w);
  if (!(t2 > 0)) return 0;
  if (type == MicrofacetType::kBeckmann) {
    // Heitz 2014, eq. 72: Lambda = (erf(a) - 1)/2 + exp(-a^2) / (2 a sqrt(pi)), a = 1 / (alpha_w tan theta).
    double a = 1 / std::sqrt(static_cast<double>(t2));
    return static_cast<float>(0.5 * (std::erf(a) - 1) + std::exp(-a * a) / (2 * a * kSqrtPi));
  }
  // Heitz 2014, eq. 86: Lambda = (-1 + sqrt(1 + alpha_w^2 tan^2 theta)) / 2.
  return 0.5f * (-1 + std::sqrt(1 + t2));
}

float MicrofacetDistribution::g1(const Vec3& w, const Vec3& m) const {
  if (masking == MaskingType::kVCavity) return vcavity_g1(w, m);
  if (dot(w, m) * w.z <= 0) return 0;
  return 1 / (1 + lambda(w));
}

float MicrofacetDistribution::g(const Vec3& wo, const Vec3& wi, const Vec3& m) const {
  if (masking == MaskingType::kVCavity) {
    // Cook & Torrance 1982 (Dutré et al., Advanced Global Illumination, 2nd ed., §2.5.4):
    //   G = min(1, 2 (N.H)(N.Theta)/(Theta.H), 2 (N.H)(N.Psi)/(Theta.H)),
    // written with each direction's own dot product, which is the same for reflection and extends to transmission.
    return std::min(vcavity_g1(wo, m), vcavity_g1(wi, m));
  }
  if (dot(wo, m) * wo.z <= 0 || dot(wi, m) * wi.z <= 0) return 0;
  return 1 / (1 + lambda(wo) + lambda(wi));
}

float MicrofacetDistribution::d_visible(const Vec3& w, const Vec3& m) const {
  if (w.z == 0) return 0;
  Vec3 mm = m.z < 0 ? -m : m;
  Vec3 ww = w.z < 0 ? -w : w;
  float wm = dot(ww, mm);
  if (wm <= 0) return 0;
  return g1(ww, mm) * wm * d(mm) / ww.z;
}

Vec3 MicrofacetDistribution::sample_normal(Vec2 u) const {
  // Slope-space sampling of D(m) cos(theta_m) (Walter 2007, eqs. 28, 35, stretched for anisotropy): Beckmann
  // slopes are Gaussian, r = sqrt(-log(1 - u)); GGX slopes have r = sqrt(u / (1 - u)).
  float ux = std::min(u.x, 1 - 1e-7f);
  float r = type == MicrofacetType::kBeckmann ? std::sqrt(-std::log(1 - ux)) : std::sqrt(ux / (1 - ux));
  float phi = 2 * kPi * u.y;
  return normalize(Vec3(-alpha_x * r * std::cos(phi), -alpha_y * r * std::sin(phi), 1));
}

Vec3 MicrofacetDistribution::sample_visible(const Vec3& w, Vec2 u, float u_extra) const {
  if (masking == MaskingType::kVCavity) {
    // V-cavity visible normals (Heitz & d'Eon 2014, section 4.2): sample m from D(m) cos(theta_m), then pick m or
    // its mirror m' = (-m_x, -m_y, m_z) in proportion to their projected areas towards w.
    Vec3 m = sample_normal(u);
    Vec3 mp(-m.x, -m.y, m.z);
    float a = std::max(0.0f, dot(w, m)), b = std::max(0.0f, dot(w, mp));
    if (a + b <= 0) return m;
    return u_extra * (a + b) < b ? mp : m;
  }
  return type == MicrofacetType::kBeckmann ? sample_beckmann_visible(*this, w, u) : sample_ggx_visible(*this, w, u);
}

float microfacet_reflection_eval(const MicrofacetDistribution& dist, const Vec3& wo, const Vec3& wi) {
  if (wo.z <= 0 || wi.z <= 0) return 0;
  Vec3 h;
  if (!reflection_half_vector(wo, wi, &h)) return 0;
  // Walter 2007, eq. 20: f = F G D / (4 |i.n| |o.n|) (F applied by the caller).
  return dist.d(h) * dist.g(wo, wi, h) / (4 * wo.z * wi.z);
}

float microfacet_reflection_pdf(const MicrofacetDistribution& dist, const Vec3& wo, const Vec3& wi) {
  if (wo.z <= 0 || wi.z <= 0) return 0;
  Vec3 h;
  if (!reflection_half_vector(wo, wi, &h)) return 0;
  float oh = dot(wo, h);
  if (oh <= 0) return 0;
  // Reflection Jacobian d(omega_h)/d(omega_i) = 1 / (4 |o.h|) (Walter 2007, eq. 14).
  return dist.d_visible(wo, h) / (4 * oh);
}

float microfacet_reflection_eval_pdf(const MicrofacetDistribution& dist, const Vec3& wo, const Vec3& wi, const Vec3& h,
                                     float* pdf) {
  *pdf = 0;
  if (wo.z <= 0 || wi.z <= 0) return 0;
  const float oh = dot(wo, h);
  if (oh <= 0) return 0;  // G and the visible-normal density both vanish
  const float d = dist.d(h);
  if (dist.masking == MaskingType::kVCavity) {
    *pdf = dist.g1(wo, h) * d / (4 * wo.z);
    return d * dist.g(wo, wi, h) / (4 * wo.z * wi.z);
  }
  // Smith: pdf = G1(o) D / (4 cos_o) with G1 = 1 / (1 + Lambda(o)); f = D / ((1 + Lambda(o) + Lambda(i)) 4 cos_o
  // cos_i).
  const float lambda_o = dist.lambda(wo);
  *pdf = d / ((1 + lambda_o) * 4 * wo.z);
  if (dot(wi, h) <= 0) return 0;
  return d / ((1 + lambda_o + dist.lambda(wi)) * (4 * wo.z * wi.z));
}

bool microfacet_reflection_sample(const MicrofacetDistribution& dist, const Vec3& wo, Vec2 u, float u_extra, Vec3* wi) {
  Vec3 m = dist.sample_visible(wo, u, u_extra);
  float om = dot(wo, m);
  if (om <= 0) return false;
  *wi = m * (2 * om) - wo;
  return wi->z > 0;
}

}  // namespace tessera
