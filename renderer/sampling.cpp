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

// An accessor of a cumulative sum stored as an array.
auto cdf_at(const double* cdf) {
  return [cdf](size_t i) { return cdf[i]; };
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
    CdfInversion::build_guide(cdf_at(cdf_.data()), n, n, guide_.data(), &slots_per_unit_);
  }
}

size_t Distribution1D::sample(float u, float* pmf, float* u_remapped) const {
  const double target = static_cast<double>(u) * cdf_.back();
  const size_t i = CdfInversion::find(cdf_at(cdf_.data()), size(), size(), guide_.empty() ? nullptr : guide_.data(),
                                      slots_per_unit_, target);
  if (pmf) *pmf = pdf_[i];
  if (u_remapped) *u_remapped = CdfInversion::remap_within(cdf_[i], cdf_[i + 1], target);
  return i;
}

Distribution2D::Distribution2D(const float* weights, int width, int height) : Distribution2D(width, height) {
  for (size_t i = 0; i < cells_.size(); ++i) cells_[i].value = Rgb(weights[i]);
  build([weights, width](int row, Cell*, float* out) {
    std::copy_n(weights + static_cast<size_t>(row) * width, width, out);
  });
}

namespace {

// `width`, once width and height are known to be sizes a Distribution2D takes (before anything is allocated).
int checked_width(int width, int height) {
  if (width < 1 || width > Distribution2D::kMaxWidth || height < 1 || height > (1 << 24))
    throw std::invalid_argument("Distribution2D: unsupported size " + std::to_string(width) + "x" +
                                std::to_string(height));
  return width;
}

}  // namespace

Distribution2D::Distribution2D(int width, int height)
    : width_(checked_width(width, height)),
      height_(height),
      area_(static_cast<float>(width) * static_cast<float>(height)),
      cells_(static_cast<size_t>(width) * height),
      row_total_(height),
      slots_((static_cast<size_t>(width) + kCellsPerSlot - 1) / kCellsPerSlot),
      guide_(static_cast<size_t>(height) * (slots_ + 1)),
      slots_per_unit_(height) {}

void Distribution2D::build(const std::function<void(int, Cell*, float*)>& row_weights) {
  const size_t n = static_cast<size_t>(width_);
  std::vector<float> marginal_weights(height_);
  auto build_rows = [&](size_t first, size_t last) {
    std::vector<float> weights(n);
    std::vector<double> sum(n + 1);
    for (size_t y = first; y < last; ++y) {
      Cell* c = &cells_[y * n];
      row_weights(static_cast<int>(y), c, weights.data());
      // Summed in double, stored in float: rounding is monotone, so the stored sums never decrease.
      const double total = cumulative_sum(weights.data(), n, sum.data());
      for (size_t x = 0; x < n; ++x) c[x].cdf = static_cast<float>(sum[x]);
      const float row_total = row_total_[y] = static_cast<float>(sum[n]);
      // The row's weight in the marginal: its stored total, or 0 for an empty row (whose cells then have equal
      // weights, should it ever be sampled).
      marginal_weights[y] = total > 0 ? row_total : 0.0f;
      CdfInversion::build_guide(row_cdf(static_cast<int>(y)), n, slots_, &guide_[y * (slots_ + 1)],
                                &slots_per_unit_[y]);
    }
  };
  // Rows are independent: built in parallel, about 64k cells per item (a 4k environment map has 2048 rows of 4096);
  // a small grid is one item, built on this thread.
  const size_t rows_per_item = std::max<size_t>(1, 65536 / n);
  run_in_parallel((static_cast<size_t>(height_) + rows_per_item - 1) / rows_per_item,
                  [&](size_t i) { build_rows(i * rows_per_item, std::min<size_t>(height_, (i + 1) * rows_per_item)); });
  marginal_ = Distribution1D(marginal_weights.data(), marginal_weights.size());
}

Vec2 Distribution2D::sample(Vec2 u, float* pdf, const Cell** cell) const {
  float ur = 0;
  const int row = static_cast<int>(marginal_.sample(u.y, nullptr, &ur));
  const auto cdf = row_cdf(row);
  const size_t n = static_cast<size_t>(width_);
  const double target = static_cast<double>(u.x) * cdf(n);
  const size_t col = CdfInversion::find(cdf, n, slots_, &guide_[static_cast<size_t>(row) * (slots_ + 1)],
                                        slots_per_unit_[row], target);
  *pdf = this->pdf(static_cast<int>(col), row);
  if (cell) *cell = &row_cells(row)[col];
  return {(col + CdfInversion::remap_within(cdf(col), cdf(col + 1), target)) / width_, (row + ur) / height_};
}

}  // namespace tessera
