// Every warp against its density: a chi-square test over a histogram whose expected counts integrate the pdf.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "renderer/sampler.h"
#include "renderer/sampling.h"
#include "tests/renderer/test_util.h"

namespace tessera {
namespace {

constexpr int kSamples = 400000;
constexpr double kAlpha = 0.001;

Vec2 uniform2(std::mt19937_64& rng) {
  std::uniform_real_distribution<float> u(0, 1);
  float a = u(rng);
  return {a, u(rng)};
}

TEST(Sampling, CosineHemisphereMatchesPdf) {
  std::mt19937_64 rng(1);
  test::DirectionHistogram h;
  for (int i = 0; i < kSamples; ++i) h.add(sample_cosine_hemisphere(uniform2(rng)));
  auto e = h.expected([](const Vec3& w) { return cosine_hemisphere_pdf(w.z); }, kSamples);
  EXPECT_GT(test::chi_square_p_value(h.counts, e), kAlpha);
}

TEST(Sampling, UniformHemisphereMatchesPdf) {
  std::mt19937_64 rng(2);
  test::DirectionHistogram h;
  for (int i = 0; i < kSamples; ++i) h.add(sample_uniform_hemisphere(uniform2(rng)));
  auto e = h.expected([](const Vec3& w) { return w.z > 0 ? uniform_hemisphere_pdf() : 0.0; }, kSamples);
  EXPECT_GT(test::chi_square_p_value(h.counts, e), kAlpha);
}

TEST(Sampling, UniformSphereMatchesPdf) {
  std::mt19937_64 rng(3);
  test::DirectionHistogram h;
  for (int i = 0; i < kSamples; ++i) h.add(sample_uniform_sphere(uniform2(rng)));
  auto e = h.expected([](const Vec3&) { return uniform_sphere_pdf(); }, kSamples);
  EXPECT_GT(test::chi_square_p_value(h.counts, e), kAlpha);
}

TEST(Sampling, UniformConeMatchesPdf) {
  std::mt19937_64 rng(4);
  const float cos_max = 0.3f;
  test::DirectionHistogram h;
  for (int i = 0; i < kSamples; ++i) h.add(sample_uniform_cone(uniform2(rng), cos_max));
  auto e = h.expected([&](const Vec3& w) { return w.z >= cos_max ? uniform_cone_pdf(cos_max) : 0.0; }, kSamples);
  EXPECT_GT(test::chi_square_p_value(h.counts, e), kAlpha);
}

TEST(Sampling, ChiSquareRejectsAWrongPdf) {
  // The harness must be able to fail: uniform hemisphere samples judged against the cosine pdf.
  std::mt19937_64 rng(5);
  test::DirectionHistogram h;
  for (int i = 0; i < kSamples; ++i) h.add(sample_uniform_hemisphere(uniform2(rng)));
  auto e = h.expected([](const Vec3& w) { return cosine_hemisphere_pdf(w.z); }, kSamples);
  EXPECT_LT(test::chi_square_p_value(h.counts, e), 1e-6);
}

// The polynomial cos/sin of the concentric map against the library's, over its whole range [-pi/4, pi/4].
TEST(Sampling, QuarterPiCosSinMatchesTheLibrary) {
  double worst = 0;
  for (int i = -100000; i <= 100000; ++i) {
    const float x = static_cast<float>(i) * (kPi / 4) / 100000;
    const Vec2 cs = cos_sin_quarter_pi(x);
    worst =
        std::max({worst, std::abs(double(cs.x) - std::cos(double(x))), std::abs(double(cs.y) - std::sin(double(x)))});
  }
  EXPECT_LT(worst, 1.5e-7);  // 2.5 float ulps at 0.7
  // And the map stays on the disk.
  for (float a : {0.0f, 0.25f, 0.5f, 0.75f, 0.999f})
    for (float b : {0.0f, 0.1f, 0.5f, 0.9f, 0.999f}) {
      const Vec2 d = sample_concentric_disk(Vec2(a, b));
      EXPECT_LE(d.x * d.x + d.y * d.y, 1.0f + 1e-6f);
    }
}

TEST(Sampling, ConcentricDiskIsUniform) {
  std::mt19937_64 rng(6);
  // Histogram over (r^2, angle): uniform on the disk means uniform in both.
  const int rows = 16, cols = 32;
  std::vector<double> counts(rows * cols, 0), expected(rows * cols, double(kSamples) / (rows * cols));
  for (int i = 0; i < kSamples; ++i) {
    Vec2 d = sample_concentric_disk(uniform2(rng));
    float r2 = d.x * d.x + d.y * d.y;
    ASSERT_LE(r2, 1.0f + 1e-5f);
    float a = std::atan2(d.y, d.x);
    if (a < 0) a += 2 * kPi;
    counts[std::min(rows - 1, int(r2 * rows)) * cols + std::min(cols - 1, int(a / (2 * kPi) * cols))] += 1;
  }
  EXPECT_GT(test::chi_square_p_value(counts, expected), kAlpha);
}

TEST(Sampling, TriangleIsUniform) {
  std::mt19937_64 rng(8);
  // A grid of n steps in (b1, b2) cuts the triangle into n^2 congruent small triangles: n(n+1)/2 upright cells
  // (fractional parts summing below 1) and n(n-1)/2 inverted ones. Uniform sampling fills them equally.
  const int n = 8;
  std::vector<double> counts(2 * n * n, 0), expected(2 * n * n, 0);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      if (i + j <= n - 1) expected[i * n + j] = double(kSamples) / (n * n);
      if (i + j <= n - 2) expected[n * n + i * n + j] = double(kSamples) / (n * n);
    }
  }
  for (int s = 0; s < kSamples; ++s) {
    Vec2 b = sample_uniform_triangle(uniform2(rng));
    ASSERT_GE(b.x, 0);
    ASSERT_GE(b.y, 0);
    ASSERT_LE(b.x + b.y, 1.0f + 1e-6f);
    int i = std::min(n - 1, int(b.x * n)), j = std::min(n - 1, int(b.y * n));
    bool inverted = (b.x * n - i) + (b.y * n - j) >= 1;
    counts[(inverted ? n * n : 0) + i * n + j] += 1;
  }
  EXPECT_GT(test::chi_square_p_value(counts, expected), kAlpha);
}

TEST(Sampling, Distribution1DPicksByWeight) {
  std::vector<float> w = {1, 0, 3, 6};
  Distribution1D d(w.data(), w.size());
  EXPECT_FLOAT_EQ(d.pmf(0), 0.1f);
  EXPECT_FLOAT_EQ(d.pmf(1), 0.0f);
  EXPECT_FLOAT_EQ(d.pmf(3), 0.6f);
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<double> counts(4, 0);
  for (int i = 0; i < kSamples; ++i) {
    float remapped = -1;
    size_t k = d.sample(u(rng), nullptr, &remapped);
    ASSERT_GE(remapped, 0.0f);
    ASSERT_LT(remapped, 1.0f);
    counts[k] += 1;
  }
  EXPECT_EQ(counts[1], 0);
  std::vector<double> obs = {counts[0], counts[2], counts[3]};
  std::vector<double> exp = {0.1 * kSamples, 0.3 * kSamples, 0.6 * kSamples};
  EXPECT_GT(test::chi_square_p_value(obs, exp), kAlpha);
}

// The guide table only narrows the search: for every u the index must be the one a binary search over the whole
// cumulative sum gives, on distributions with runs of empty buckets, spikes and a wide dynamic range (an
// environment map with a sun), and for u at and beside the slot boundaries k / n.
TEST(Sampling, Distribution1DGuideTableMatchesBinarySearch) {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<float> u01(0, 1);
  for (size_t n : {32u, 33u, 100u, 512u, 4099u}) {
    std::vector<float> w(n);
    for (size_t i = 0; i < n; ++i) {
      const float r = u01(rng);
      w[i] = r < 0.3f ? 0.0f : (r > 0.995f ? 1e6f * r : std::exp(20 * (r - 0.5f)));
    }
    Distribution1D d(w.data(), n);
    std::vector<double> cdf(n + 1, 0);
    for (size_t i = 0; i < n; ++i) cdf[i + 1] = cdf[i] + std::max(0.0f, w[i]);
    auto reference = [&](float u) {
      const double target = static_cast<double>(u) * cdf.back();
      size_t i = static_cast<size_t>(std::upper_bound(cdf.begin() + 1, cdf.end(), target) - cdf.begin() - 1);
      i = std::min(i, n - 1);
      while (i + 1 < n && d.pmf(i) == 0) ++i;
      return i;
    };
    std::vector<float> us;
    for (int k = 0; k < 20000; ++k) us.push_back(u01(rng));
    for (size_t k = 0; k <= n; ++k) {
      const float at = static_cast<float>(static_cast<double>(k) / static_cast<double>(n));
      for (float v : {std::nextafter(at, 0.0f), at, std::nextafter(at, 1.0f)})
        if (v >= 0 && v < 1) us.push_back(v);
    }
    us.push_back(0.0f);
    us.push_back(std::nextafter(1.0f, 0.0f));
    for (float v : us) ASSERT_EQ(d.sample(v), reference(v)) << "n " << n << " u " << v;
  }
}

// The 2D distribution picks cells in proportion to their weights (chi-square over the cells), never an empty cell
// or a cell of an empty row, reports for each sample the density pdf(col, row) of its cell, and spreads points
// uniformly inside a cell (chi-square over quarters of the heaviest cell).
TEST(Sampling, Distribution2DPicksCellsByWeight) {
  const int w = 40, h = 6;  // wider than a guide table's threshold in 1D: the rows always have one
  std::vector<float> weights(w * h);
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<float> u01(0, 1);
  for (int i = 0; i < w * h; ++i) weights[i] = u01(rng) < 0.2f ? 0.0f : std::exp(4 * u01(rng));
  for (int x = 0; x < w; ++x) weights[2 * w + x] = 0;  // an empty row
  weights[5 * w + 7] = 500;                            // a sun
  Distribution2D d(weights.data(), w, h);
  double total = 0;
  for (float v : weights) total += v;
  const int n = 400000;
  std::vector<double> cells(w * h, 0), quarters(4, 0);
  for (int i = 0; i < n; ++i) {
    float pdf = 0;
    const Distribution2D::Cell* cell = nullptr;
    const Vec2 p = d.sample(Vec2(u01(rng), u01(rng)), &pdf, &cell);
    ASSERT_GE(p.x, 0.0f);
    ASSERT_LT(p.x, 1.0f);
    ASSERT_GE(p.y, 0.0f);
    ASSERT_LT(p.y, 1.0f);
    const int col = std::min(w - 1, static_cast<int>(p.x * w)), row = std::min(h - 1, static_cast<int>(p.y * h));
    ASSERT_GT(weights[row * w + col], 0) << "cell " << col << ", " << row;
    ASSERT_FLOAT_EQ(pdf, d.pdf(col, row));
    ASSERT_EQ(cell, &d.cell(col, row));
    ASSERT_EQ(cell->value, Rgb(weights[row * w + col]));
    cells[row * w + col] += 1;
    if (col == 7 && row == 5) quarters[(p.x * w - col < 0.5f ? 0 : 1) + (p.y * h - row < 0.5f ? 0 : 2)] += 1;
  }
  std::vector<double> observed, expected;
  double integral = 0;
  for (int i = 0; i < w * h; ++i) {
    integral += d.pdf(i % w, i / w) / (w * h);
    if (weights[i] <= 0) continue;
    EXPECT_NEAR(d.pdf(i % w, i / w), weights[i] / total * w * h, 1e-4 * weights[i] / total * w * h);
    observed.push_back(cells[i]);
    expected.push_back(n * weights[i] / total);
  }
  EXPECT_NEAR(integral, 1.0, 1e-5);
  EXPECT_GT(test::chi_square_p_value(observed, expected), kAlpha);
  const double in_sun = quarters[0] + quarters[1] + quarters[2] + quarters[3];
  EXPECT_GT(test::chi_square_p_value(quarters, std::vector<double>(4, in_sun / 4)), kAlpha);
}

TEST(Sampling, PowerHeuristic) {
  EXPECT_FLOAT_EQ(power_heuristic(1, 1), 0.5f);
  EXPECT_FLOAT_EQ(power_heuristic(3, 1), 0.9f);
  EXPECT_FLOAT_EQ(power_heuristic(1, 0), 1.0f);
  EXPECT_FLOAT_EQ(power_heuristic(0, 0), 0.0f);
  EXPECT_NEAR(power_heuristic(2, 5) + power_heuristic(5, 2), 1.0f, 1e-6);
}

TEST(PixelSampler, IsDeterministicAndUniform) {
  PixelSampler a(42, 1000, 7), b(42, 1000, 7), c(42, 1000, 8);
  for (int i = 0; i < 16; ++i) {
    float va = a.get1d();
    EXPECT_EQ(va, b.get1d());
    EXPECT_NE(va, c.get1d());
  }
  // Uniformity of one dimension across pixels and samples.
  const int bins = 50;
  std::vector<double> counts(bins, 0);
  int n = 0;
  for (uint32_t px = 0; px < 2000; ++px) {
    for (uint64_t s = 0; s < 100; ++s) {
      PixelSampler ps(1, px, s);
      ps.get1d();
      float v = ps.get1d();
      ASSERT_GE(v, 0.0f);
      ASSERT_LT(v, 1.0f);
      counts[int(v * bins)] += 1;
      ++n;
    }
  }
  EXPECT_GT(test::chi_square_p_value(counts, std::vector<double>(bins, double(n) / bins)), kAlpha);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Owen scrambling and index shuffling keep Sobol's (0,2)-sequence property: the first 2^k samples of any pixel's
// dimension pair put exactly one point in every elementary interval of area 2^-k.
TEST(SobolSampler, FirstPowerOfTwoSamplesFormA02Net) {
  for (uint32_t pixel : {0u, 17u, 123456u}) {
    for (int pair = 0; pair < 4; ++pair) {
      for (int k = 1; k <= 8; ++k) {
        const uint32_t n = 1u << k;
        std::vector<Vec2> pts;
        for (uint32_t s = 0; s < n; ++s) {
          PixelSampler ps(9, pixel, s, SamplerKind::kSobol);
          Vec2 p;
          for (int d = 0; d <= pair; ++d) p = ps.get2d();
          pts.push_back(p);
        }
        for (int a = 0; a <= k; ++a) {
          const int cols = 1 << a, rows = 1 << (k - a);
          std::vector<int> cells(n, 0);
          for (Vec2 p : pts) cells[int(p.y * rows) * cols + int(p.x * cols)]++;
          for (int c : cells) ASSERT_EQ(c, 1) << "pixel " << pixel << " pair " << pair << " k " << k << " a " << a;
        }
      }
    }
  }
}

TEST(SobolSampler, IsUniformAcrossPixelsAndDecorrelatedBetweenPairs) {
  const int bins = 16;
  std::vector<double> counts(bins * bins, 0);
  int n = 0;
  double corr = 0;
  for (uint32_t px = 0; px < 4000; ++px) {
    for (uint64_t s = 0; s < 16; ++s) {
      PixelSampler ps(3, px, s, SamplerKind::kSobol);
      Vec2 a = ps.get2d();
      Vec2 b = ps.get2d();
      ASSERT_LT(a.x, 1.0f);
      ASSERT_LT(b.y, 1.0f);
      // The joint distribution of one coordinate of pair 0 and one of pair 1 must be uniform on the square.
      counts[int(a.x * bins) * bins + int(b.x * bins)] += 1;
      corr += (a.x - 0.5) * (b.x - 0.5);
      ++n;
    }
  }
  EXPECT_GT(test::chi_square_p_value(counts, std::vector<double>(bins * bins, double(n) / (bins * bins))), 0.001);
  EXPECT_NEAR(corr / n * 12, 0.0, 0.02);  // correlation coefficient
}

}  // namespace
}  // namespace tessera
