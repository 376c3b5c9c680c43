#include <gtest/gtest.h>

#include "renderer/camera.h"
#include "renderer/sampler.h"
#include "renderer/sampling.h"

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

// Cameras for the importance tests: a pinhole and a thin lens, looking somewhere off the axes, wider than tall.
CameraDesc importance_camera(float aperture) {
  CameraDesc d;
  d.from = Vec3(0.5f, 1, 3);
  d.to = Vec3(0, 0.2f, -1);
  d.fov_deg = 50;
  d.aperture_radius = aperture;
  d.focus_distance = 3;
  return d;
}

// Monte Carlo estimate of the integral of W_e |cos theta| over the lens area and every direction (uniform on the
// sphere): 1 for a camera normalised over its whole image (Veach 1997, 4.5; pbrt-v4 5.4.1). Also the integral of the
// direction density, which must be 1 too.
void importance_integrals(const Camera& cam, double* we_integral, double* pdf_integral) {
  constexpr int kN = 400000;
  double sum_we = 0, sum_pdf = 0;
  for (int i = 0; i < kN; ++i) {
    PixelSampler s(7, 0, static_cast<uint64_t>(i));
    const Vec2 u_lens = s.get2d();
    Ray ray;
    ray.origin = cam.desc().from;
    if (cam.uses_lens()) {
      Frame f = Frame::from_normal(cam.forward());
      const Vec2 l = sample_concentric_disk(u_lens) * cam.desc().aperture_radius;
      ray.origin = ray.origin + f.to_world(Vec3(l.x, l.y, 0));
    }
    ray.dir = sample_uniform_sphere(s.get2d());
    const float cos_theta = std::abs(dot(ray.dir, cam.forward()));
    // Lens point uniform by area (density 1 / A_lens), direction uniform on the sphere (1 / 4 pi).
    sum_we += cam.importance(ray) * cos_theta * cam.lens_area() * 4 * kPi;
    float pdf_pos, pdf_dir;
    cam.importance_pdf(ray, &pdf_pos, &pdf_dir);
    sum_pdf += pdf_dir * 4 * kPi;
  }
  *we_integral = sum_we / kN;
  *pdf_integral = sum_pdf / kN;
}

TEST(CameraImportance, IntegratesToOneOverLensAndImage) {
  for (float aperture : {0.0f, 0.15f}) {
    SCOPED_TRACE(aperture);
    Camera cam(importance_camera(aperture), 64, 40);
    double we, pdf;
    importance_integrals(cam, &we, &pdf);
    // About 1.5 % of the directions land in the image: the standard error is about 1 % of the mean.
    EXPECT_NEAR(we, 1.0, 0.04);
    EXPECT_NEAR(pdf, 1.0, 0.04);
  }
}

TEST(CameraImportance, IsZeroOutsideTheImageAndBehindTheCamera) {
  Camera cam(importance_camera(0), 64, 40);
  Ray r = cam.generate_ray(Vec2(32, 20), Vec2());
  EXPECT_GT(cam.importance(r), 0);
  r.dir = -r.dir;
  EXPECT_EQ(cam.importance(r), 0);
  Ray past_edge = cam.generate_ray(Vec2(64.5f, 20), Vec2());
  EXPECT_EQ(cam.importance(past_edge), 0);
  Ray inside_edge = cam.generate_ray(Vec2(63.9f, 0.1f), Vec2());
  EXPECT_GT(cam.importance(inside_edge), 0);
  CameraDesc ortho;
  ortho.projection = CameraDesc::Projection::kOrthographic;
  EXPECT_FALSE(Camera(ortho, 8, 8).has_importance());
}

TEST(CameraImportance, FilmPositionRoundTripsThroughGenerateRay) {
  // The film position importance() reports for a generated ray is the one it was generated from; the W_e at the
  // image centre is 1 / (A A_lens).
  for (float aperture : {0.0f, 0.15f}) {
    SCOPED_TRACE(aperture);
    Camera cam(importance_camera(aperture), 64, 40);
    for (Vec2 px : {Vec2(0.5f, 0.5f), Vec2(32, 20), Vec2(63.25f, 7.5f), Vec2(10.75f, 39.5f)}) {
      const Vec2 u_lens(0.3f, 0.8f);
      Ray r = cam.generate_ray(px, u_lens);
      Vec2 film;
      ASSERT_GT(cam.importance(r, &film), 0);
      EXPECT_NEAR(film.x, px.x, 2e-3);
      EXPECT_NEAR(film.y, px.y, 2e-3);
    }
    const float half_h = std::tan(25 * kPi / 180), half_w = half_h * 64 / 40;
    EXPECT_NEAR(cam.importance(cam.generate_ray(Vec2(32, 20), Vec2(0.5f, 0.5f))),
                1 / (4 * half_w * half_h * cam.lens_area()), 1e-3);
  }
}

TEST(CameraImportance, SampledLensPointSeesTheReferencePoint) {
  // sample_importance from a point: the ray from the lens point to it lands on the pixel generate_ray would make it
  // from with the same lens sample (the point is on that ray), and the density is the lens's area density turned to
  // solid angle at the point.
  for (float aperture : {0.0f, 0.15f}) {
    SCOPED_TRACE(aperture);
    Camera cam(importance_camera(aperture), 64, 40);
    int seen = 0;
    for (int i = 0; i < 200; ++i) {
      PixelSampler s(3, 0, static_cast<uint64_t>(i));
      const Vec3 ref = Vec3(0, 0.2f, -1) + Vec3(s.get1d() - 0.5f, s.get1d() - 0.5f, s.get1d() - 0.5f) * 3;
      const Vec2 u_lens = s.get2d();
      CameraImportanceSample cs;
      if (!cam.sample_importance(ref, u_lens, &cs)) continue;
      ++seen;
      EXPECT_NEAR(length(ref + cs.wi * cs.dist - cs.p_lens), 0, 1e-4);
      Ray r = cam.generate_ray(cs.film, u_lens);
      EXPECT_NEAR(length(r.origin - cs.p_lens), 0, 1e-4);
      EXPECT_NEAR(dot(r.dir, -cs.wi), 1, 1e-5);
      const float cos_lens = std::abs(dot(cs.wi, cam.forward()));
      EXPECT_NEAR(cs.pdf, cs.dist * cs.dist / (cos_lens * cam.lens_area()), 1e-3 * cs.pdf);
      if (aperture == 0) {
        Vec2 projected;
        ASSERT_TRUE(cam.project(ref, &projected));
        EXPECT_NEAR(projected.x, cs.film.x, 1e-3);
        EXPECT_NEAR(projected.y, cs.film.y, 1e-3);
      }
    }
    EXPECT_GT(seen, 50);
  }
}

}  // namespace
}  // namespace tessera
