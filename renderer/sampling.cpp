#include "renderer/sampling.h"

#include <algorithm>

namespace tessera {

Vec3 sample_uniform_hemisphere(Vec2 u) {
  float z = u.x;
  float r = safe_sqrt(1 - z * z);
  float phi = 2 * kPi * u.y;
  return {r * std::cos(phi), r * std::sin(phi), z};
}

Vec3 sample_uniform_sphere(Vec2 u) {
  float z = 1 - 2 * u.x;
  float r = safe_sqrt(1 - z * z);
  float phi = 2 * kPi * u.y;
  return {r * std::cos(phi), r * std::sin(phi), z};
}

Vec3 sample_uniform_cone(Vec2 u, float cos_theta_max) {
  float cos_theta = (1 - u.x) + u.x * cos_theta_max;
  float sin_theta = safe_sqrt(1 - cos_theta * cos_theta);
  float phi = 2 * kPi * u.y;
  return {sin_theta * std::cos(phi), sin_theta * std::sin(phi), cos_theta};
}

Distribution1D::Distribution1D(const float* weights, size_t n) : pdf_(n), cdf_(n + 1) {
  cdf_[0] = 0;
  for (size_t i = 0; i < n; ++i) cdf_[i + 1] = cdf_[i] + std::max(0.0f, weights[i]);
  total_ = cdf_[n];
  for (size_t i = 0; i < n; ++i) {
    pdf_[i] = total_ > 0 ? static_cast<float>(std::max(0.0f, weights[i]) / total_) : 1.0f / static_cast<float>(n);
  }
  if (!(total_ > 0)) {
    for (size_t i = 0; i <= n; ++i) cdf_[i] = static_cast<double>(i);
    total_ = 0;
  }
  // Below a few dozen buckets the binary search is as fast as the table.
  if (n >= 32 && n < (size_t(1) << 31)) {
    guide_.resize(n + 1);
    slots_per_unit_ = static_cast<double>(n) / cdf_.back();
    size_t i = 0;
    for (size_t k = 0; k < n; ++k) {
      while (i + 1 < n && slot(cdf_[i + 1]) < k) ++i;
      guide_[k] = static_cast<uint32_t>(i);
    }
    guide_[n] = static_cast<uint32_t>(n - 1);
  }
}

size_t Distribution1D::sample(float u, float* pmf, float* u_remapped) const {
  const double scale = cdf_.back();
  const double target = static_cast<double>(u) * scale;
  // First bucket whose upper bound exceeds the target, skipping empty buckets.
  auto first = cdf_.begin() + 1, last = cdf_.end();
  if (!guide_.empty()) {
    const size_t k = slot(target);
    first = cdf_.begin() + 1 + guide_[k];
    last = cdf_.begin() + 2 + guide_[k + 1];
  }
  auto it = std::upper_bound(first, last, target);
  size_t i = static_cast<size_t>(std::min<std::ptrdiff_t>(it - cdf_.begin() - 1, static_cast<std::ptrdiff_t>(size() - 1)));
  while (i + 1 < size() && pdf_[i] == 0) ++i;
  if (pmf) *pmf = pdf_[i];
  if (u_remapped) {
    double width = cdf_[i + 1] - cdf_[i];
    double r = width > 0 ? (target - cdf_[i]) / width : 0.5;
    *u_remapped = static_cast<float>(std::clamp(r, 0.0, 0.99999994));
  }
  return i;
}

}  // namespace tessera
