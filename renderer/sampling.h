// Warps from the unit square to the domains the path tracer integrates over, each with its density
// (the seeds' chapter on Monte Carlo integration: sample proportionally to the integrand's known factors).
#pragma once

#include <vector>

#include "renderer/math.h"

namespace tessera {

// cos and sin of an angle in [-pi/4, pi/4], by their Taylor polynomials to x^8 and x^9: truncation errors below
// 2.5e-8 at pi/4 (under half a float ulp there). The library call they replace ran at every path vertex.
inline Vec2 cos_sin_quarter_pi(float x) {
  const float x2 = x * x;
  const float c = 1 + x2 * (-1.0f / 2 + x2 * (1.0f / 24 + x2 * (-1.0f / 720 + x2 * (1.0f / 40320))));
  const float s = x * (1 + x2 * (-1.0f / 6 + x2 * (1.0f / 120 + x2 * (-1.0f / 5040 + x2 * (1.0f / 362880)))));
  return {c, s};
}

// Uniform on the unit disk, by Shirley and Chiu's concentric map (area-preserving, low distortion). Inline, with
// the next two: they run at every path vertex.
inline Vec2 sample_concentric_disk(Vec2 u) {
  float ox = 2 * u.x - 1, oy = 2 * u.y - 1;
  if (ox == 0 && oy == 0) return {0, 0};
  if (std::abs(ox) > std::abs(oy)) {
    // theta = pi/4 * oy/ox, in [-pi/4, pi/4].
    const Vec2 cs = cos_sin_quarter_pi((kPi / 4) * (oy / ox));
    return {ox * cs.x, ox * cs.y};
  }
  // theta = pi/2 - a with a = pi/4 * ox/oy in [-pi/4, pi/4]: cos theta = sin a, sin theta = cos a.
  const Vec2 cs = cos_sin_quarter_pi((kPi / 4) * (ox / oy));
  return {oy * cs.y, oy * cs.x};
}
// Cosine-weighted on the hemisphere z > 0: pdf = cos(theta) / pi. Malley's method: the uniform disk projected up.
inline Vec3 sample_cosine_hemisphere(Vec2 u) {
  Vec2 d = sample_concentric_disk(u);
  return {d.x, d.y, safe_sqrt(1 - d.x * d.x - d.y * d.y)};
}
inline float cosine_hemisphere_pdf(float cos_theta) { return cos_theta > 0 ? cos_theta * kInvPi : 0.0f; }
// Uniform on the hemisphere z > 0: pdf = 1 / (2 pi).
Vec3 sample_uniform_hemisphere(Vec2 u);
inline constexpr float uniform_hemisphere_pdf() { return kInv2Pi; }
// Uniform on the unit sphere: pdf = 1 / (4 pi).
Vec3 sample_uniform_sphere(Vec2 u);
inline constexpr float uniform_sphere_pdf() { return kInv4Pi; }
// Uniform in the cone around +z with the given cos of its half-angle: pdf = 1 / (2 pi (1 - cos_max)).
Vec3 sample_uniform_cone(Vec2 u, float cos_theta_max);
inline float uniform_cone_pdf(float cos_theta_max) { return 1.0f / (2 * kPi * (1 - cos_theta_max)); }
// Uniform on a triangle: barycentric coordinates (b1, b2) of the second and third vertex (Heitz, "A Low-Distortion
// Map Between Triangle and Square", 2019).
inline Vec2 sample_uniform_triangle(Vec2 u) {
  float b0, b1;
  if (u.x < u.y) {
    b0 = u.x / 2;
    b1 = u.y - b0;
  } else {
    b1 = u.y / 2;
    b0 = u.x - b1;
  }
  return {b1, 1 - b0 - b1};
}

// Veach's power heuristic with beta = 2, for two strategies taking one sample each.
inline float power_heuristic(float pdf_a, float pdf_b) {
  float a = pdf_a * pdf_a, b = pdf_b * pdf_b;
  if (std::isinf(a)) return 1.0f;
  return a + b > 0 ? a / (a + b) : 0.0f;
}

// A discrete distribution over n weights, sampled by inverting its cumulative sum. A guide table (Chen and Asau's
// cutpoint method) narrows the search to the buckets one n-th of the total can span: O(1) on average, and the
// same index as a binary search over the whole sum for every u.
class Distribution1D {
 public:
  Distribution1D() = default;
  explicit Distribution1D(const float* weights, size_t n);
  size_t size() const { return pdf_.size(); }
  bool empty() const { return pdf_.empty(); }
  // Picks index i with probability pdf(i); `u` in [0,1). `u_remapped` (optional) receives u rescaled to [0,1) within
  // the chosen bucket, so one uniform number can serve twice.
  size_t sample(float u, float* pmf = nullptr, float* u_remapped = nullptr) const;
  float pmf(size_t i) const { return pdf_[i]; }
  double total() const { return total_; }

 private:
  // The guide slot of a target in [0, total): monotone in the target, one multiply. The table is built with this
  // same function, so no rounding of it can send a target to a slot whose range misses the answer.
  size_t slot(double target) const {
    const double k = target * slots_per_unit_;
    return k < static_cast<double>(guide_.size() - 2) ? static_cast<size_t>(k) : guide_.size() - 2;
  }
  std::vector<float> pdf_;
  std::vector<double> cdf_;  // n + 1 entries
  // Empty for small n; else n + 1 entries (n slots): guide_[k] is the first bucket i with slot(cdf_[i + 1]) >= k
  // (guide_[n] = n - 1). The answer for a target in slot k lies in buckets guide_[k] .. guide_[k + 1]: its bucket's
  // upper bound is above the target (so in slot k or later), its lower bound at or below (so in slot k or earlier).
  std::vector<uint32_t> guide_;
  double slots_per_unit_ = 0;
  double total_ = 0;
};

}  // namespace tessera
