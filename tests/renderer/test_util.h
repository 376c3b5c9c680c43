// Shared helpers for renderer tests: chi-square statistics and small scenes built in code.
#pragma once

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "renderer/math.h"
#include "renderer/scene_error.h"
#include "renderer/scene_loader.h"
#include "renderer/session.h"

namespace tessera::test {

// Expects loading `doc` (at pointer "/scene") to fail at `pointer` with a message that holds `words`, as a 422 names
// the field.
inline void expect_scene_error(const nlohmann::json& doc, const std::string& pointer, const std::string& words = "") {
  try {
    load_scene(doc, "/scene", SceneLoadOptions{});
    ADD_FAILURE() << "no error for " << pointer;
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), pointer) << e.what();
    EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
  }
}

// A scene document rendered with `settings` on every core: the film's resolved RGB.
inline std::vector<float> render_document(const nlohmann::json& scene_doc, const RenderSettings& settings) {
  auto scene = load_scene(scene_doc, "/scene", SceneLoadOptions{});
  ThreadPool pool(0);
  RenderSession session(scene, settings, pool);
  session.run();
  return session.film().resolve();
}

// Regularised upper incomplete gamma Q(a, x), for the chi-square survival function (Numerical Recipes 6.2).
inline double gamma_q(double a, double x) {
  if (x <= 0) return 1.0;
  const double gln = std::lgamma(a);
  if (x < a + 1) {
    double ap = a, sum = 1.0 / a, del = sum;
    for (int n = 0; n < 10000; ++n) {
      ap += 1;
      del *= x / ap;
      sum += del;
      if (std::abs(del) < std::abs(sum) * 1e-15) break;
    }
    return std::max(0.0, 1.0 - sum * std::exp(-x + a * std::log(x) - gln));
  }
  double b = x + 1 - a, c = 1e300, d = 1 / b, h = d;
  for (int i = 1; i < 10000; ++i) {
    double an = -i * (i - a);
    b += 2;
    d = an * d + b;
    if (std::abs(d) < 1e-300) d = 1e-300;
    c = b + an / c;
    if (std::abs(c) < 1e-300) c = 1e-300;
    d = 1 / d;
    double del = d * c;
    h *= del;
    if (std::abs(del - 1) < 1e-15) break;
  }
  return std::exp(-x + a * std::log(x) - gln) * h;
}

// Pearson's chi-square test of observed against expected counts, pooling cells expected below 5 into one.
// Returns the p-value.
inline double chi_square_p_value(const std::vector<double>& observed, const std::vector<double>& expected) {
  double chi2 = 0, pooled_obs = 0, pooled_exp = 0;
  int dof = -1;
  for (size_t i = 0; i < observed.size(); ++i) {
    if (expected[i] < 5) {
      pooled_obs += observed[i];
      pooled_exp += expected[i];
      continue;
    }
    chi2 += (observed[i] - expected[i]) * (observed[i] - expected[i]) / expected[i];
    ++dof;
  }
  if (pooled_exp >= 5) {
    chi2 += (pooled_obs - pooled_exp) * (pooled_obs - pooled_exp) / pooled_exp;
    ++dof;
  } else if (pooled_obs > 0 && pooled_exp == 0) {
    return 0.0;  // samples where the density is zero
  }
  if (dof < 1) return 1.0;
  return gamma_q(dof / 2.0, chi2 / 2.0);
}

// Integrates f over [a0,a1]x[b0,b1] with 2-point Gauss-Legendre rules on an n x n grid of sub-cells. The nodes lie
// strictly inside every sub-cell, so a density that jumps on a cell boundary is integrated exactly per side.
inline double integrate_2d(const std::function<double(double, double)>& f, double a0, double a1, double b0, double b1,
                           int n = 6) {
  const double g = 0.5 / std::sqrt(3.0);
  double ha = (a1 - a0) / n, hb = (b1 - b0) / n, sum = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      double ca = a0 + (i + 0.5) * ha, cb = b0 + (j + 0.5) * hb;
      for (double sa : {-g, g})
        for (double sb : {-g, g}) sum += f(ca + sa * ha, cb + sb * hb);
    }
  return sum * ha * hb / 4.0;
}

// Histogram of directions over (cos theta in [-1,1], phi in [0, 2pi)); cells have equal solid angle.
struct DirectionHistogram {
  int rows = 20, cols = 40;
  std::vector<double> counts = std::vector<double>(rows * cols, 0.0);
  void add(const Vec3& w) {
    float z = clamp(w.z, -1.0f, 1.0f);
    int r = std::min(rows - 1, static_cast<int>((z + 1) * 0.5f * rows));
    float phi = std::atan2(w.y, w.x);
    if (phi < 0) phi += 2 * kPi;
    int c = std::min(cols - 1, static_cast<int>(phi / (2 * kPi) * cols));
    counts[r * cols + c] += 1;
  }
  // Expected counts from a pdf over solid angle, integrated over each cell in (cos theta, phi).
  std::vector<double> expected(const std::function<double(const Vec3&)>& pdf, int n, int subdivisions = 6) const {
    std::vector<double> e(rows * cols);
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        double z0 = -1 + 2.0 * r / rows, z1 = -1 + 2.0 * (r + 1) / rows;
        double p0 = 2 * M_PI * c / cols, p1 = 2 * M_PI * (c + 1) / cols;
        e[r * cols + c] = n * integrate_2d(
                                  [&](double z, double phi) {
                                    double s = std::sqrt(std::max(0.0, 1 - z * z));
                                    return pdf(Vec3(static_cast<float>(s * std::cos(phi)),
                                                    static_cast<float>(s * std::sin(phi)), static_cast<float>(z)));
                                  },
                                  z0, z1, p0, p1, subdivisions);
      }
    }
    return e;
  }
};

// Region means of K independent renders and their standard errors: the spread of each region's mean over the runs,
// for comparing independent unbiased estimators of one image (Student's t on K - 1 degrees of freedom).
struct RegionStats {
  std::vector<double> mean, se;
};

// `image(k)` renders run k, a size x size image of RGB floats (row-major); it is cut into regions x regions squares,
// each channel kept apart.
inline RegionStats grid_region_stats(int runs, int size, int regions,
                                     const std::function<std::vector<float>(int k)>& image) {
  std::vector<std::vector<double>> per_run(runs, std::vector<double>(regions * regions * 3, 0));
  const int r = size / regions;
  for (int k = 0; k < runs; ++k) {
    const std::vector<float> img = image(k);
    for (int y = 0; y < size; ++y)
      for (int x = 0; x < size; ++x)
        for (int c = 0; c < 3; ++c)
          per_run[k][((y / r) * regions + x / r) * 3 + c] += img[(y * size + x) * 3 + c] / double(r * r);
  }
  RegionStats s;
  for (size_t i = 0; i < per_run[0].size(); ++i) {
    double m = 0, v = 0;
    for (int k = 0; k < runs; ++k) m += per_run[k][i] / runs;
    for (int k = 0; k < runs; ++k) v += (per_run[k][i] - m) * (per_run[k][i] - m) / (runs - 1);
    s.mean.push_back(m);
    s.se.push_back(std::sqrt(v / runs));
  }
  return s;
}

// Largest |z| of the differences between two estimates, region by region and channel by channel; `scale_b` scales
// the second (a test's check that the comparison would see a bias of that size).
inline double worst_z(const RegionStats& a, const RegionStats& b, double scale_b = 1.0) {
  double worst = 0;
  for (size_t i = 0; i < a.mean.size(); ++i) {
    const double se = std::sqrt(a.se[i] * a.se[i] + b.se[i] * b.se[i] * scale_b * scale_b);
    worst = std::max(worst, std::abs(a.mean[i] - b.mean[i] * scale_b) / std::max(se, 1e-6 + 1e-4 * a.mean[i]));
  }
  return worst;
}

}  // namespace tessera::test
