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
