#include <gtest/gtest.h>

#include <filesystem>
#include <random>

#include <OpenImageIO/imageio.h>

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
      integral +=
          map->pdf(Vec3(float(s * std::cos(phi)), float(s * std::sin(phi)), float(z))) * (4 * M_PI / (rows * cols));
    }
  EXPECT_NEAR(integral, 1.0, 0.02);
}

TEST(EnvironmentMap, AverageIsSolidAngleWeighted) {
  std::vector<float> rgb(16 * 8 * 3, 0.5f);
  EnvironmentMap flat(16, 8, rgb);
  EXPECT_NEAR(flat.average().y, 0.5f, 1e-5);
  EXPECT_NEAR(flat.lookup(Vec3(0, 1, 0)).x, 0.5f, 1e-5);
}

// Surfaces are lit by the texel a direction falls in: the radiance sample() returns is exactly the lighting() of the
// direction it returns, with the same density. What is seen is filtered: at a texel's centre it is the texel, halfway
// between two texel centres their mean.
TEST(EnvironmentMap, LightingIsTheSampledTexelAndWhatIsSeenIsFiltered) {
  const int w = 32, h = 16;
  std::vector<float> rgb(static_cast<size_t>(w) * h * 3);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> u(0, 1);
  for (float& v : rgb) v = 0.1f + 10 * u(rng) * u(rng);
  const EnvironmentMap map(w, h, rgb);
  auto texel = [&](int x, int y) {
    const float* p = &rgb[(static_cast<size_t>(y) * w + x) * 3];
    return Rgb(p[0], p[1], p[2]);
  };
  int same = 0;
  const int n = 4000;
  for (int i = 0; i < n; ++i) {
    float pdf = 0, lit_pdf = 0;
    Rgb sampled;
    const Vec3 d = map.sample(Vec2(u(rng), u(rng)), &pdf, &sampled);
    const Rgb lit = map.lighting(d, &lit_pdf);
    const Vec2 uv = EnvironmentMap::direction_to_uv(d);
    const Rgb in = texel(std::min(w - 1, static_cast<int>(uv.x * w)), std::min(h - 1, static_cast<int>(uv.y * h)));
    // A direction within float rounding of a texel edge may convert back into the neighbour: allow a few.
    same += sampled == lit && lit == in && std::abs(pdf - lit_pdf) <= 1e-3f * pdf;
  }
  EXPECT_GE(same, n * 99 / 100);
  for (int y = 1; y < h - 1; ++y)
    for (int x = 1; x < w - 2; ++x) {
      const Rgb centre = map.lookup(EnvironmentMap::uv_to_direction(Vec2((x + 0.5f) / w, (y + 0.5f) / h)));
      const Rgb between = map.lookup(EnvironmentMap::uv_to_direction(Vec2((x + 1.0f) / w, (y + 0.5f) / h)));
      const Rgb mean = (texel(x, y) + texel(x + 1, y)) * 0.5f;
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(centre[c], texel(x, y)[c], 2e-3f * texel(x, y)[c]) << x << ", " << y;
        EXPECT_NEAR(between[c], mean[c], 2e-3f * mean[c]) << x << ", " << y;
      }
    }
}

// A map read from a file lands in its texels as stored, with values that are not finite or are negative made 0 and
// huge ones clamped.
TEST(EnvironmentMap, LoadsAFileWithBadValuesMadeSafe) {
  const int w = 8, h = 4;
  std::vector<float> rgb(static_cast<size_t>(w) * h * 3);
  for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = 0.25f * static_cast<float>(i % 7);
  rgb[3 * 9] = std::nanf("");
  rgb[3 * 10 + 1] = -5;
  rgb[3 * 11 + 2] = std::numeric_limits<float>::infinity();
  rgb[3 * 12] = 3e38f;  // finite, but a row of such texels would overflow the sampling sums
  const auto path = std::filesystem::temp_directory_path() / ("tessera-env-" + std::to_string(::getpid()) + ".exr");
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out && out->open(path.string(), OIIO::ImageSpec(w, h, 3, OIIO::TypeDesc::FLOAT)) &&
              out->write_image(OIIO::TypeDesc::FLOAT, rgb.data()));
  out->close();
  auto map = EnvironmentMap::load(path.string());
  std::filesystem::remove(path);
  ASSERT_EQ(map->width(), w);
  ASSERT_EQ(map->height(), h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float pdf = 0;
      const Rgb lit = map->lighting(EnvironmentMap::uv_to_direction(Vec2((x + 0.5f) / w, (y + 0.5f) / h)), &pdf);
      // Finite densities; in the clamped texel's row the texels after it are lost in its float sum (density 0: never
      // light-sampled, so paths that reach them by BSDF sampling keep their full weight).
      EXPECT_TRUE(std::isfinite(pdf));
      if (y != 1) {
        EXPECT_GT(pdf, 0) << x << ", " << y;
      }
      for (int c = 0; c < 3; ++c) {
        const float v = rgb[(static_cast<size_t>(y) * w + x) * 3 + c];
        EXPECT_EQ(lit[c], std::isfinite(v) && v > 0 ? std::min(v, EnvironmentMap::kMaxRadiance) : 0.0f)
            << x << ", " << y << ", " << c;
      }
    }
}

}  // namespace
}  // namespace tessera
