// Warps from the unit square to the domains the path tracer integrates over, each with its density
// (the seeds' chapter on Monte Carlo integration: sample proportionally to the integrand's known factors).
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <vector>

#include "renderer/math.h"

namespace tessera {

// cos and sin of an angle in [-pi/4, pi/4], by their Taylor polynomials to x^8 and x^9: truncation errors below
// 2.5e-8 at pi/4 (under half a float ulp there). The library call they replace ran at every path vertex.
// Evaluated by Estrin's scheme (pairs of terms in parallel, then combined by x^4) rather than Horner's: the path's
// next direction waits on this, and the chain of dependent operations is half as long.
inline Vec2 cos_sin_quarter_pi(float x) {
  const float x2 = x * x, x4 = x2 * x2;
  const float c = (1 - x2 * (1.0f / 2)) + x4 * ((1.0f / 24 - x2 * (1.0f / 720)) + x4 * (1.0f / 40320));
  const float s = x * ((1 - x2 * (1.0f / 6)) + x4 * ((1.0f / 120 - x2 * (1.0f / 5040)) + x4 * (1.0f / 362880)));
  return {c, s};
}

// Uniform on the unit disk, by Shirley and Chiu's concentric map (area-preserving, low distortion). Inline, with
// the next two: they run at every path vertex. Written with selects, not branches: which of |x| and |y| is larger is
// a coin toss per sample, and a mispredicted branch cost more than the map.
inline Vec2 sample_concentric_disk(Vec2 u) {
  const float ox = 2 * u.x - 1, oy = 2 * u.y - 1;
  // The major axis' coordinate is the radius (signed); theta = pi/4 * minor/major in [-pi/4, pi/4] from it. At the
  // centre both are 0 and the angle is taken as 0.
  const FloatMask x_major = greater_mask(std::abs(ox), std::abs(oy));
  const float major = select(x_major, ox, oy), minor = select(x_major, oy, ox);
  const Vec2 cs = cos_sin_quarter_pi((kPi / 4) * (minor / (major != 0 ? major : 1.0f)));
  // About the y axis the angle is pi/2 - theta: cos and sin swap.
  return {major * select(x_major, cs.x, cs.y), major * select(x_major, cs.y, cs.x)};
}
// Cosine-weighted on the hemisphere z > 0: pdf = cos(theta) / pi. Malley's method: the uniform disk projected up.
inline Vec3 sample_cosine_hemisphere(Vec2 u) {
  Vec2 d = sample_concentric_disk(u);
  return {d.x, d.y, safe_sqrt(1 - d.x * d.x - d.y * d.y)};
}
inline float cosine_hemisphere_pdf(float cos_theta) {
  return cos_theta > 0 ? cos_theta * kInvPi : 0.0f;
}
// Uniform on the hemisphere z > 0: pdf = 1 / (2 pi).
Vec3 sample_uniform_hemisphere(Vec2 u);
inline constexpr float uniform_hemisphere_pdf() {
  return kInv2Pi;
}
// Uniform on the unit sphere: pdf = 1 / (4 pi).
Vec3 sample_uniform_sphere(Vec2 u);
inline constexpr float uniform_sphere_pdf() {
  return kInv4Pi;
}
// Uniform in the cone around +z with the given cos of its half-angle: pdf = 1 / (2 pi (1 - cos_max)).
Vec3 sample_uniform_cone(Vec2 u, float cos_theta_max);
inline float uniform_cone_pdf(float cos_theta_max) {
  return 1.0f / (2 * kPi * (1 - cos_theta_max));
}
// Uniform on a triangle: barycentric coordinates (b1, b2) of the second and third vertex (Heitz, "A Low-Distortion
// Map Between Triangle and Square", 2019).
inline Vec2 sample_uniform_triangle(Vec2 u) {
  // The smaller coordinate is halved and the other one shifted by it; selects, not a branch (a coin toss per sample).
  const FloatMask x_smaller = greater_mask(u.y, u.x);
  const float half = select(x_smaller, u.x, u.y) / 2;
  const float b0 = select(x_smaller, half, u.x - half);
  const float b1 = select(x_smaller, u.y - half, half);
  return {b1, 1 - b0 - b1};
}

// Veach's power heuristic with beta = 2, for two strategies taking one sample each.
inline float power_heuristic(float pdf_a, float pdf_b) {
  float a = pdf_a * pdf_a, b = pdf_b * pdf_b;
  if (std::isinf(a)) return 1.0f;
  return a + b > 0 ? a / (a + b) : 0.0f;
}

// Inversion of a cumulative sum (n + 1 entries from cdf(0) = 0, read through an accessor so the sum may be stored
// apart or interleaved with other data) with a guide table (Chen and Asau's cutpoint method) that narrows the search
// to the buckets one n-th of the total can span: O(1) on average, and the same index as a binary search over the
// whole sum for every target. Shared by the 1D and 2D distributions below.
struct CdfInversion {
  // guide[k] (m + 1 entries for m slots) is the first bucket i with slot(cdf(i + 1)) >= k, guide[m] = n - 1. The
  // answer for a target in slot k lies in buckets guide[k] .. guide[k + 1]: its bucket's upper bound is above the
  // target (so in slot k or later), its lower bound at or below (so in slot k or earlier). With m = n slots the range
  // holds about one bucket; fewer slots make a smaller table and longer ranges. Guide entries are 32-bit, or 16-bit
  // where n - 1 fits (the rows of a 2D distribution).
  template <typename Cdf, typename Guide>
  static void build_guide(const Cdf& cdf, size_t n, size_t m, Guide* guide, double* slots_per_unit) {
    *slots_per_unit = static_cast<double>(m) / cdf(n);
    size_t i = 0;
    for (size_t k = 0; k < m; ++k) {
      while (i + 1 < n && slot(cdf(i + 1), *slots_per_unit, m) < k) ++i;
      guide[k] = static_cast<Guide>(i);
    }
    guide[m] = static_cast<Guide>(n - 1);
  }
  // The first bucket with a non-zero width whose upper bound exceeds `target` in [0, cdf(n)); `guide` (of m slots)
  // may be null (a binary search over the whole sum).
  template <typename Cdf, typename Guide>
  static size_t find(const Cdf& cdf, size_t n, size_t m, const Guide* guide, double slots_per_unit, double target) {
    // The first j in [first, last) with cdf(j) > target (an upper bound); the bucket is j - 1.
    size_t first = 1, last = n + 1;
    if (guide) {
      const size_t k = slot(target, slots_per_unit, m);
      first = 1 + guide[k];
      last = 2 + guide[k + 1];
    }
    // Halving with a select instead of a branch (Khuong and Morin's layout-free form): the number of steps depends
    // only on the range's length, and the side taken, a coin toss, costs no misprediction. `base` stays the last
    // probed entry at or below the target, or the range's start.
    size_t base = first;
    for (size_t len = last - first; len > 1;) {
      const size_t half = len / 2;
      base = cdf(base + half) <= target ? base + half : base;
      len -= half;
    }
    if (cdf(base) <= target) ++base;
    size_t i = std::min(base - 1, n - 1);
    while (i + 1 < n && !(cdf(i + 1) > cdf(i))) ++i;
    return i;
  }
  // The guide slot (of m) of a target: monotone in the target, one multiply. The table is built with this same
  // function, so no rounding of it can send a target to a slot whose range misses the answer.
  static size_t slot(double target, double slots_per_unit, size_t m) {
    const double k = target * slots_per_unit;
    return k < static_cast<double>(m - 1) ? static_cast<size_t>(k) : m - 1;
  }
  // u in [0,1) rescaled to [0,1) within a bucket [lo, hi) of the sum, for the target that found it.
  static float remap_within(double lo, double hi, double target) {
    const double width = hi - lo;
    const double r = width > 0 ? (target - lo) / width : 0.5;
    return static_cast<float>(std::clamp(r, 0.0, 0.99999994));
  }
};

// A discrete distribution over n weights, sampled by inverting its cumulative sum (CdfInversion).
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
  std::vector<float> pdf_;
  std::vector<double> cdf_;      // n + 1 entries
  std::vector<uint32_t> guide_;  // empty below a few dozen buckets (a binary search is as fast), else n + 1 entries
  double slots_per_unit_ = 0;
  double total_ = 0;
};

// A piecewise-constant density on the unit square over a width x height grid of non-negative weights (row-major,
// row 0 first), sampled by inversion: a row from the marginal distribution, then a column from that row's
// conditional one, then a uniform point in the cell. Low-discrepancy points stay well spread in the image of the
// map. Each cell carries a colour (an environment map's radiance) beside the row's cumulative weight before it, in
// 16 bytes: sampling a cell, reading its density and reading its colour touch the same cache line, where separate
// arrays of colours, sums and densities cost a cache miss each (most of the time of a 4k environment map's light
// sampling). The sums are floats: the uniform numbers that invert them are on a 2^-24 grid anyway, and a cell's
// density is computed from the same stored sums its sampling inverts, so the two always agree.
class Distribution2D {
 public:
  struct alignas(16) Cell {
    Rgb value;
    float cdf = 0;  // the row's weights summed before this cell
  };
  // Widest row it takes: its guide tables are 16-bit.
  static constexpr int kMaxWidth = 65535;

 private:
  // (Ahead of the members that use it: a deduced return type must be seen first.)
  const Cell* row_cells(int row) const { return &cells_[static_cast<size_t>(row) * width_]; }
  // A row's cumulative sum as CdfInversion reads it: cdf(i) for i in 0..width, cdf(width) the row's total.
  auto row_cdf(int row) const {
    return [c = row_cells(row), n = static_cast<size_t>(width_), total = row_total_[row]](size_t i) -> double {
      return i < n ? c[i].cdf : total;
    };
  }

 public:
  Distribution2D() = default;
  // A grid whose cells hold weights[i] both as their weight and as their value.
  Distribution2D(const float* weights, int width, int height);
  // A grid of cells whose values the caller writes (through cells()) before build(); throws std::invalid_argument
  // for a size outside 1..kMaxWidth x 1..2^24, before anything is allocated.
  Distribution2D(int width, int height);
  Cell* cells() { return cells_.data(); }
  // Makes the distribution: row_weights(row, cells, weights) writes the weights of a row's cells, and may adjust
  // their values first (rows are built in parallel, each call with its own array).
  void build(const std::function<void(int row, Cell* cells, float* weights)>& row_weights);

  // A point of the unit square with density *pdf (over the unit square); u in [0,1)^2. `cell`, when given, receives
  // the cell the point is in.
  Vec2 sample(Vec2 u, float* pdf, const Cell** cell = nullptr) const;
  // The density at cell (col, row), the one sample() reports for points in it.
  float pdf(int col, int row) const {
    const auto cdf = row_cdf(row);
    return marginal_.pmf(row) * static_cast<float>((cdf(col + 1) - cdf(col)) / cdf(width_)) * area_;
  }
  const Cell& cell(int col, int row) const { return row_cells(row)[col]; }
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  int width_ = 0, height_ = 0;
  float area_ = 0;  // width * height: a cell's probability times this is its density
  std::vector<Cell> cells_;
  Distribution1D marginal_;       // of rows
  std::vector<float> row_total_;  // per row: the sum of its weights (its cdf past the last cell)
  // A row's guide table has a slot per kCellsPerSlot cells: a quarter of the memory of one per cell (the table is read
  // at random, like the cells), and the range it leaves is about one cache line of cells.
  static constexpr int kCellsPerSlot = 4;
  size_t slots_ = 0;
  std::vector<uint16_t> guide_;         // height rows of slots_ + 1 entries: each row's guide table
  std::vector<double> slots_per_unit_;  // per row
};
static_assert(sizeof(Distribution2D::Cell) == 4 * sizeof(float), "a cell is four floats: colour and sum");

}  // namespace tessera
