#include <gtest/gtest.h>

#include <random>

#include "renderer/math.h"

namespace tessera {
namespace {

TEST(Frame, IsOrthonormalForEveryNormal) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> u(-1, 1);
  for (int i = 0; i < 10000; ++i) {
    Vec3 n = normalize(Vec3(u(rng), u(rng), u(rng)));
    if (i == 0) n = Vec3(0, 0, -1);  // the singular case of the naive construction
    if (i == 1) n = Vec3(0, 0, 1);
    Frame f = Frame::from_normal(n);
    EXPECT_NEAR(length(f.s), 1, 1e-5);
    EXPECT_NEAR(length(f.t), 1, 1e-5);
    EXPECT_NEAR(dot(f.s, f.t), 0, 1e-5);
    EXPECT_NEAR(dot(f.s, f.n), 0, 1e-5);
    EXPECT_NEAR(dot(f.t, f.n), 0, 1e-5);
    // Right-handed: s x t = n.
    Vec3 c = cross(f.s, f.t);
    EXPECT_NEAR(c.x, n.x, 1e-5);
    EXPECT_NEAR(c.y, n.y, 1e-5);
    EXPECT_NEAR(c.z, n.z, 1e-5);
  }
}

TEST(Frame, LocalWorldRoundTrip) {
  Frame f = Frame::from_normal_tangent(normalize(Vec3(1, 2, 3)), Vec3(1, 0, 0));
  Vec3 v(0.3f, -0.2f, 0.9f);
  Vec3 back = f.to_world(f.to_local(v));
  EXPECT_NEAR(back.x, v.x, 1e-6);
  EXPECT_NEAR(back.y, v.y, 1e-6);
  EXPECT_NEAR(back.z, v.z, 1e-6);
  EXPECT_NEAR(f.to_local(f.n).z, 1, 1e-6);
  // The tangent direction is kept (projected into the plane).
  EXPECT_GT(dot(f.s, Vec3(1, 0, 0)), 0.5f);
}

TEST(Vec3, ReflectMirrorsAboutNormal) {
  Vec3 wo = normalize(Vec3(1, 0, 1));
  Vec3 r = reflect(wo, Vec3(0, 0, 1));
  EXPECT_NEAR(r.x, -wo.x, 1e-6);
  EXPECT_NEAR(r.z, wo.z, 1e-6);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// fast_atan2 against the library in double, over every direction of a fine circle at several radii, the axes and
// signed zeros: within 5e-7 rad, two float ulps at pi (the polynomial is within 2e-8; the rest is float rounding).
TEST(FastAtan2, MatchesTheLibrary) {
  double worst = 0;
  for (float radius : {1e-30f, 1e-3f, 1.0f, 7.5f, 1e20f})
    for (int i = 0; i < 100000; ++i) {
      const double a = -M_PI + 2 * M_PI * (i + 0.5) / 100000;
      const float x = static_cast<float>(radius * std::cos(a)), y = static_cast<float>(radius * std::sin(a));
      worst = std::max(worst, std::abs(fast_atan2(y, x) - std::atan2(static_cast<double>(y), static_cast<double>(x))));
    }
  EXPECT_LT(worst, 5e-7);
  for (float y : {0.0f, -0.0f, 1.0f, -1.0f})
    for (float x : {0.0f, -0.0f, 1.0f, -1.0f, 3.0f})
      EXPECT_NEAR(fast_atan2(y, x), std::atan2(y, x), 3e-7) << "atan2(" << y << ", " << x << ")";
  EXPECT_EQ(std::signbit(fast_atan2(-0.0f, -1.0f)), std::signbit(std::atan2(-0.0f, -1.0f)));
}

}  // namespace
}  // namespace tessera
