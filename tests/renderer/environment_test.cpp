#include <gtest/gtest.h>

#include <random>

#include "renderer/environment.h"
#include "tests/renderer/test_util.h"

namespace tessera {
namespace {

// A map that is dim everywhere but for a bright spot, like a sky with a sun.
std::shared_ptr<EnvironmentMap> sun_map(int w = 64, int h = 32) {
  std::vector<float> rgb(static_cast<size_t>(w) * h * 3, 0.2f);
  for (int y = 8; y < 12; ++y)
    for (int x = 40; x < 44; ++x)
      for (int c = 0; c < 3; ++c) rgb[(static_cast<size_t>(y) * w + x) * 3 + c] = 200.0f;
  return std::make_shared<EnvironmentMap>(w, h, std::move(rgb));
}

TEST(EnvironmentMap, UvDirectionRoundTrip) {
  for (Vec2 uv : {Vec2(0.1f, 0.2f), Vec2(0.5f, 0.5f), Vec2(0.9f, 0.8f), Vec2(0.25f, 0.01f)}) {
    Vec3 d = EnvironmentMap::uv_to_direction(uv);
    EXPECT_NEAR(length(d), 1, 1e-5);
    Vec2 back = EnvironmentMap::direction_to_uv(d);
    EXPECT_NEAR(back.x, uv.x, 1e-5);
    EXPECT_NEAR(back.y, uv.y, 1e-5);
  }
  EXPECT_NEAR(EnvironmentMap::uv_to_direction(Vec2(0.5f, 0.0f)).y, 1, 1e-6);  // v = 0 is straight up
}

TEST(EnvironmentMap, SamplingMatchesPdf) {
  auto map = sun_map();
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<float> u(0, 1);
  const int n = 400000;
  test::DirectionHistogram h;
  for (int i = 0; i < n; ++i) {
    float pdf = 0;
    Vec3 d = map->sample(Vec2(u(rng), u(rng)), &pdf);
    ASSERT_GT(pdf, 0);
    // The returned density is the one pdf() reports for the same direction.
    if (i < 2000) {
      float p = map->pdf(d);
      ASSERT_NEAR(pdf, p, 1e-3f * p + 1e-4f);
    }
    h.add(d);
  }
  // The pdf jumps at texel edges (1000:1 at the sun): integrate each cell finely.
  auto e = h.expected([&](const Vec3& d) { return map->pdf(d); }, n, 32);
  EXPECT_GT(test::chi_square_p_value(h.counts, e), 0.001);
  // Most samples go towards the sun.
  int toward_sun = 0;
  for (int i = 0; i < 10000; ++i) {
    float pdf;
    Vec2 uv = EnvironmentMap::direction_to_uv(map->sample(Vec2(u(rng), u(rng)), &pdf));
    toward_sun += uv.x >= 40 / 64.0f && uv.x < 44 / 64.0f && uv.y >= 8 / 32.0f && uv.y < 12 / 32.0f;
  }
  EXPECT_GT(toward_sun, 9000);
}

TEST(EnvironmentMap, PdfIntegratesToOne) {
  auto map = sun_map();
  double integral = 0;
  const int rows = 200, cols = 400;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      double z = -1 + 2.0 * (r + 0.5) / rows, phi = 2 * M_PI * (c + 0.5) / cols, s = std::sqrt(1 - z * z);
      integral += map->pdf(Vec3(float(s * std::cos(phi)), float(s * std::sin(phi)), float(z))) * (4 * M_PI / (rows * cols));
    }
  EXPECT_NEAR(integral, 1.0, 0.02);
}

TEST(EnvironmentMap, AverageIsSolidAngleWeighted) {
  std::vector<float> rgb(16 * 8 * 3, 0.5f);
  EnvironmentMap flat(16, 8, rgb);
  EXPECT_NEAR(flat.average().y, 0.5f, 1e-5);
  EXPECT_NEAR(flat.lookup(Vec3(0, 1, 0)).x, 0.5f, 1e-5);
}

}  // namespace
}  // namespace tessera
