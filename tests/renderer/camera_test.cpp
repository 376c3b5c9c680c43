#include <gtest/gtest.h>

#include "renderer/camera.h"

namespace tessera {
namespace {

TEST(Camera, CentreRayLooksAtTarget) {
  CameraDesc d;
  d.from = Vec3(1, 2, 3);
  d.to = Vec3(1, 2, -7);
  Camera cam(d, 64, 48);
  Ray r = cam.generate_ray(Vec2(32, 24), Vec2(0.5f, 0.5f));
  EXPECT_NEAR(r.dir.x, 0, 1e-6);
  EXPECT_NEAR(r.dir.y, 0, 1e-6);
  EXPECT_NEAR(r.dir.z, -1, 1e-6);
}

TEST(Camera, VerticalFieldOfViewSpansTheImageHeight) {
  CameraDesc d;
  d.from = Vec3(0, 0, 0);
  d.to = Vec3(0, 0, -1);
  d.fov_deg = 60;
  Camera cam(d, 200, 100);
  Ray top = cam.generate_ray(Vec2(100, 0), Vec2(0.5f, 0.5f));
  float angle = std::acos(dot(top.dir, Vec3(0, 0, -1))) * 180 / kPi;
  EXPECT_NEAR(angle, 30, 1e-3);
  EXPECT_GT(top.dir.y, 0);  // image row 0 is the top
  Ray right = cam.generate_ray(Vec2(200, 50), Vec2(0.5f, 0.5f));
  EXPECT_GT(right.dir.x, 0);  // image right is world right for a camera looking down -z with +y up
  // Horizontal half-angle follows the aspect ratio.
  float h = std::atan(std::tan(30 * kPi / 180) * 2) * 180 / kPi;
  EXPECT_NEAR(std::acos(dot(right.dir, Vec3(0, 0, -1))) * 180 / kPi, h, 1e-3);
}

TEST(Camera, ProjectInvertsGenerateRay) {
  CameraDesc d;
  d.from = Vec3(0.3f, 1, 4);
  d.to = Vec3(0, 0.5f, 0);
  d.fov_deg = 45;
  Camera cam(d, 320, 240);
  for (Vec2 px : {Vec2(10, 10), Vec2(160, 120), Vec2(300.5f, 17.25f), Vec2(1, 239)}) {
    Ray r = cam.generate_ray(px, Vec2(0.5f, 0.5f));
    Vec2 back;
    ASSERT_TRUE(cam.project(r.origin + r.dir * 3.7f, &back));
    EXPECT_NEAR(back.x, px.x, 1e-3);
    EXPECT_NEAR(back.y, px.y, 1e-3);
  }
}

TEST(Camera, ThinLensRaysMeetOnTheFocusPlane) {
  CameraDesc d;
  d.from = Vec3(0, 0, 0);
  d.to = Vec3(0, 0, -5);
  d.aperture_radius = 0.2f;
  d.focus_distance = 5;
  Camera cam(d, 100, 100);
  Vec2 px(70, 40);
  Ray a = cam.generate_ray(px, Vec2(0.1f, 0.9f));
  Ray b = cam.generate_ray(px, Vec2(0.8f, 0.3f));
  EXPECT_GT(length(a.origin - b.origin), 0.01f);
  // Both reach the plane z = -5 at the same point.
  Vec3 pa = a.origin + a.dir * ((-5 - a.origin.z) / a.dir.z);
  Vec3 pb = b.origin + b.dir * ((-5 - b.origin.z) / b.dir.z);
  EXPECT_NEAR(pa.x, pb.x, 1e-4);
  EXPECT_NEAR(pa.y, pb.y, 1e-4);
}

TEST(Camera, OrthographicRaysAreParallel) {
  CameraDesc d;
  d.projection = CameraDesc::Projection::kOrthographic;
  d.from = Vec3(0, 0, 10);
  d.to = Vec3(0, 0, 0);
  d.ortho_height = 4;
  Camera cam(d, 100, 50);
  Ray a = cam.generate_ray(Vec2(0, 0), Vec2());
  Ray b = cam.generate_ray(Vec2(100, 50), Vec2());
  EXPECT_NEAR(dot(a.dir, b.dir), 1, 1e-6);
  EXPECT_NEAR(a.origin.y - b.origin.y, 4, 1e-5);  // the view is `height` tall
  EXPECT_NEAR(b.origin.x - a.origin.x, 8, 1e-5);  // and height * aspect wide
}

}  // namespace
}  // namespace tessera
