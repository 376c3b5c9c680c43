#include "renderer/sampling.h"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "renderer/thread_pool.h"

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

namespace {

// The cumulative sum of n weights (negative ones as zero) into cdf[0..n]; a uniform one when they sum to zero.
// Returns the sum.
double cumulative_sum(const float* weights, size_t n, double* cdf) {
  cdf[0] = 0;
  for (size_t i = 0; i < n; ++i) cdf[i + 1] = cdf[i] + std::max(0.0f, weights[i]);
  const double total = cdf[n];
  if (!(total > 0))
    for (size_t i = 0; i <= n; ++i) cdf[i] = static_cast<double>(i);
  return total > 0 ? total : 0;
}

// u in [0,1) rescaled to [0,1) within bucket i of the sum, for a target u * cdf[n].
float remap_within(const double* cdf, size_t i, double target) {
  const double width = cdf[i + 1] - cdf[i];
  const double r = width > 0 ? (target - cdf[i]) / width : 0.5;
  return static_cast<float>(std::clamp(r, 0.0, 0.99999994));
}

}  // namespace

Distribution1D::Distribution1D(const float* weights, size_t n) : pdf_(n), cdf_(n + 1) {
  total_ = cumulative_sum(weights, n, cdf_.data());
  for (size_t i = 0; i < n; ++i) {
    pdf_[i] = total_ > 0 ? static_cast<float>(std::max(0.0f, weights[i]) / total_) : 1.0f / static_cast<float>(n);
  }
  // Below a few dozen buckets the binary search is as fast as the table.
  if (n >= 32 && n < (size_t(1) << 31)) {
    guide_.resize(n + 1);
    CdfInversion::build_guide(cdf_.data(), n, guide_.data(), &slots_per_unit_);
  }
}

size_t Distribution1D::sample(float u, float* pmf, float* u_remapped) const {
  const double target = static_cast<double>(u) * cdf_.back();
  const size_t i =
      CdfInversion::find(cdf_.data(), size(), guide_.empty() ? nullptr : guide_.data(), slots_per_unit_, target);
  if (pmf) *pmf = pdf_[i];
  if (u_remapped) *u_remapped = remap_within(cdf_.data(), i, target);
  return i;
}

Distribution2D::Distribution2D(const float* weights, int width, int height)
    : Distribution2D(width, height, [weights, width](int row, float* out) {
        std::copy_n(weights + static_cast<size_t>(row) * width, width, out);
      }) {}

namespace {

// `width`, once width and height are known to be sizes a Distribution2D takes (before anything is allocated).
int checked_width(int width, int height) {
  if (width < 1 || width > Distribution2D::kMaxWidth || height < 1 || height > (1 << 24))
    throw std::invalid_argument("Distribution2D: unsupported size " + std::to_string(width) + "x" +
                                std::to_string(height));
  return width;
}

}  // namespace

Distribution2D::Distribution2D(int width, int height, const std::function<void(int, float*)>& fill_row)
    : width_(checked_width(width, height)),
      height_(height),
      cells_(static_cast<float>(width) * static_cast<float>(height)),
      cdf_(static_cast<size_t>(height) * (width + 1)),
      guide_(static_cast<size_t>(height) * (width + 1)),
      slots_per_unit_(height) {
  std::vector<float> row_weights(height);
  auto build_rows = [&](size_t first, size_t last) {
    std::vector<float> weights(width);
    for (size_t y = first; y < last; ++y) {
      fill_row(static_cast<int>(y), weights.data());
      double* c = &cdf_[y * (width + 1)];
      row_weights[y] = static_cast<float>(cumulative_sum(weights.data(), width, c));
      CdfInversion::build_guide(c, width, &guide_[y * (width + 1)], &slots_per_unit_[y]);
    }
  };
  // Rows are independent: built in parallel, about 64k cells per item (a 4k environment map has 2048 rows of 4096);
  // a small grid is one item, built on this thread.
  const size_t rows_per_item = std::max<size_t>(1, 65536 / static_cast<size_t>(width));
  run_in_parallel((static_cast<size_t>(height) + rows_per_item - 1) / rows_per_item, [&](size_t i) {
    build_rows(i * rows_per_item, std::min<size_t>(height, (i + 1) * rows_per_item));
  });
  marginal_ = Distribution1D(row_weights.data(), row_weights.size());
}

Vec2 Distribution2D::sample(Vec2 u, float* pdf) const {
  float ur = 0;
  const int row = static_cast<int>(marginal_.sample(u.y, nullptr, &ur));
  const double* c = row_cdf(row);
  const double target = static_cast<double>(u.x) * c[width_];
  const int col = static_cast<int>(CdfInversion::find(c, width_, &guide_[static_cast<size_t>(row) * (width_ + 1)],
                                                      slots_per_unit_[row], target));
  *pdf = this->pdf(col, row);
  return {(col + remap_within(c, col, target)) / width_, (row + ur) / height_};
}

}  // namespace tessera
