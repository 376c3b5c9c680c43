// Lights as the start of light paths: sampled emitted rays carry, on average, the closed-form power each light
// emits (the radiant flux of Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed., §4.1.5: radiance
// integrated over the emitting points and the directions they emit to, with the cosine), and the densities reported
// afterwards for a ray are those it was sampled with.
#include <gtest/gtest.h>

#include "renderer/sampler.h"
#include "renderer/scene.h"

namespace tessera {
namespace {

using nlohmann::json;

uint32_t add_material(Scene& scene, const json& params) {
  scene.materials.push_back(MaterialRegistry::builtin().create(params, "/m", MaterialContext{}));
  scene.material_names.push_back(std::string("m").append(std::to_string(scene.materials.size())));
  return static_cast<uint32_t>(scene.materials.size() - 1);
}

// A grey diffuse unit sphere at the origin: the scene's bounds (radius sqrt(3)) for lights at infinity.
void add_ball(Scene& scene) {
  scene.spheres.push_back({Vec3(0), 1, add_material(scene, {{"type", "lambert"}, {"albedo", 0.5}}), 0, {}});
}

// A rectangle emitting `radiance`, of area 0.5 x 0.8, tilted.
void add_panel(Scene& scene, float radiance, bool one_sided) {
  Mesh m;
  const Vec3 c(0.2f, 1.5f, -0.3f), e1(0.5f, 0, 0), e2(0, 0.48f, 0.64f);
  m.positions = {c, c + e1, c + e1 + e2, c + e2};
  m.indices = {0, 1, 2, 0, 2, 3};
  m.material =
      add_material(scene, {{"type", "lambert"}, {"albedo", 0.2}, {"emission", radiance}, {"one_sided", one_sided}});
  scene.meshes.push_back(std::move(m));
}

struct PowerEstimate {
  double mean = 0, stderr_ = 0;
};

// Mean and standard error of LightEmission::weight() (red channel) over n samples: the total emitted power.
PowerEstimate emitted_power(const Scene& scene, int n = 200000) {
  double sum = 0, sum2 = 0;
  for (int i = 0; i < n; ++i) {
    PixelSampler s(11, 3, static_cast<uint64_t>(i));
    const float u_select = s.get1d();
    const Vec2 u_pos = s.get2d(), u_dir = s.get2d();
    LightEmission le;
    double w = 0;
    if (scene.lights().sample_emission(u_select, u_pos, u_dir, &le)) w = le.weight().x;
    sum += w;
    sum2 += w * w;
  }
  PowerEstimate e;
  e.mean = sum / n;
  e.stderr_ = std::sqrt(std::max(0.0, sum2 / n - e.mean * e.mean) / (n - 1));
  return e;
}

void expect_power(const Scene& scene, double expected) {
  const PowerEstimate e = emitted_power(scene);
  EXPECT_NEAR(e.mean, expected, std::max(4 * e.stderr_, 2e-3 * expected)) << "stderr " << e.stderr_;
  EXPECT_NEAR(e.mean, expected, 0.02 * expected);
}

TEST(LightEmission, AreaLightsEmitTheirClosedFormPower) {
  for (bool one_sided : {true, false}) {
    SCOPED_TRACE(one_sided);
    Scene scene;
    add_panel(scene, 3, one_sided);
    scene.finalize();
    // A Lambertian emitter of radiance L and area A emits pi A L to each side it emits to.
    expect_power(scene, (one_sided ? 1 : 2) * kPi * 0.4 * 3);
  }
  Scene scene;
  scene.spheres.push_back({Vec3(1, 0, 0), 0.5f, add_material(scene, {{"type", "emission"}, {"radiance", 2}}), 0, {}});
  scene.finalize();
  const auto& mat = *scene.materials[0];
  expect_power(scene, (mat.emission_one_sided() ? 1 : 2) * kPi * 4 * kPi * 0.25 * 2);
}

TEST(LightEmission, PunctualLightsEmitTheirClosedFormPower) {
  Scene scene;
  add_ball(scene);
  PunctualLight point;
  point.position = Vec3(0, 3, 0);
  point.intensity = Rgb(5);
  scene.finalize_with_lights({point});
  expect_power(scene, 4 * kPi * 5);  // an isotropic intensity I over the sphere of directions

  PunctualLight spot = point;
  spot.kind = PunctualLight::Kind::kSpot;
  spot.direction = normalize(Vec3(0.3f, -1, 0.1f));
  spot.cos_inner = std::cos(20 * kPi / 180);
  spot.cos_outer = std::cos(40 * kPi / 180);
  scene.finalize_with_lights({spot});
  // I over the inner cone, and I t^2 with t linear in cos from the outer to the inner cone: a third of that band.
  expect_power(scene, 2 * kPi * 5 * (1 - spot.cos_inner + (spot.cos_inner - spot.cos_outer) / 3));

  PunctualLight sun;
  sun.kind = PunctualLight::Kind::kDirectional;
  sun.direction = normalize(Vec3(1, -2, 0.5f));
  sun.intensity = Rgb(4);
  scene.finalize_with_lights({sun});
  // Irradiance E through the disc of the scene's bounding sphere (radius sqrt(3)).
  expect_power(scene, 4 * kPi * 3);
}

TEST(LightEmission, EnvironmentEmitsThroughTheBoundingDisc) {
  Scene scene;
  add_ball(scene);
  scene.environment.color = Rgb(0.7f);
  scene.finalize();
  // Radiance L from every direction through a disc of radius R: 4 pi x pi R^2 x L.
  expect_power(scene, 4 * kPi * kPi * 3 * 0.7);

  // A map: bright band around the horizon, a hot spot; its power is pi R^2 times its integral over directions,
  // 4 pi times its solid-angle average.
  const int w = 64, h = 32;
  std::vector<float> rgb(static_cast<size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float v = 0.2f + (y > 12 && y < 20 ? 1.5f : 0.0f) + (x == 40 && y == 8 ? 50.0f : 0.0f);
      for (int c = 0; c < 3; ++c) rgb[3 * (static_cast<size_t>(y) * w + x) + c] = v;
    }
  scene.environment.color = Rgb(1);
  scene.environment.rotation_deg = 30;
  scene.environment.map = std::make_shared<EnvironmentMap>(w, h, rgb);
  scene.finalize();
  expect_power(scene, 4 * kPi * kPi * 3 * scene.environment.average().x);
}

TEST(LightEmission, SeveralLightsSumTheirPowers) {
  Scene scene;
  add_panel(scene, 3, true);
  scene.environment.color = Rgb(0.1f);
  PunctualLight point;
  point.position = Vec3(0, 3, 0);
  point.intensity = Rgb(2);
  scene.finalize_with_lights({point});
  const double r2 = length_squared(scene.bounds().hi - scene.bounds().lo) / 4;
  expect_power(scene, kPi * 0.4 * 3 + 4 * kPi * 2 + 4 * kPi * kPi * r2 * 0.1);
}

TEST(LightEmission, EmittedTowardsOtherDirections) {
  Scene scene;
  add_panel(scene, 3, true);
  PunctualLight spot;
  spot.kind = PunctualLight::Kind::kSpot;
  spot.position = Vec3(0, 2, 0);
  spot.direction = Vec3(0, -1, 0);
  spot.cos_inner = 0.9f;
  spot.cos_outer = 0.8f;
  spot.intensity = Rgb(2);
  scene.finalize_with_lights({spot});
  bool saw_panel = false, saw_spot = false;
  for (int i = 0; i < 64; ++i) {
    PixelSampler s(2, 0, static_cast<uint64_t>(i));
    const float u_select = s.get1d();
    const Vec2 u_pos = s.get2d(), u_dir = s.get2d();
    LightEmission le;
    if (!scene.lights().sample_emission(u_select, u_pos, u_dir, &le)) continue;
    if (le.spot) {
      saw_spot = true;
      EXPECT_EQ(le.emitted(Vec3(0, -1, 0)), Rgb(2));             // inside the inner cone
      EXPECT_EQ(le.emitted(normalize(Vec3(1, -1, 0))), Rgb(0));  // outside the outer cone
      EXPECT_NEAR(le.emitted(normalize(Vec3(0.6f, -0.85f, 0))).x,
                  2 * sqr((0.85f / std::sqrt(0.36f + 0.7225f) - 0.8f) / 0.1f), 1e-4);
    } else {
      saw_panel = true;
      EXPECT_EQ(le.emitted(le.n), Rgb(3));
      EXPECT_EQ(le.emitted(-le.n), Rgb(0));  // one-sided
    }
  }
  EXPECT_TRUE(saw_panel && saw_spot);
}

TEST(LightEmission, ReportedDensitiesAreThoseSampled) {
  Scene scene;
  add_panel(scene, 3, false);
  const int w = 16, h = 8;
  std::vector<float> rgb(static_cast<size_t>(w) * h * 3, 0.5f);
  rgb[3 * 20] = 20;
  scene.environment.color = Rgb(1);
  scene.environment.map = std::make_shared<EnvironmentMap>(w, h, rgb);
  PunctualLight spot;
  spot.kind = PunctualLight::Kind::kSpot;
  spot.position = Vec3(0, 2, 0);
  spot.direction = Vec3(0, -1, 0);
  spot.cos_outer = 0.8f;
  PunctualLight point;
  point.position = Vec3(1, 2, 0);
  scene.finalize_with_lights({spot, point});
  const float r = scene.bounds().radius();
  int checked = 0;
  for (int i = 0; i < 4000; ++i) {
    PixelSampler s(5, 0, static_cast<uint64_t>(i));
    const float u_select = s.get1d();
    const Vec2 u_pos = s.get2d(), u_dir = s.get2d();
    LightEmission le;
    if (!scene.lights().sample_emission(u_select, u_pos, u_dir, &le)) continue;
    float pdf_pos, pdf_dir;
    scene.lights().emission_pdf(le.light, le.n, le.ray.dir, &pdf_pos, &pdf_dir);
    EXPECT_NEAR(pdf_pos, le.pdf_pos, 1e-4f * le.pdf_pos);
    EXPECT_NEAR(pdf_dir, le.pdf_dir, 2e-3f * le.pdf_dir);
    EXPECT_EQ(le.delta_pos, scene.lights().delta_position(le.light));
    if (!le.infinite) {
      EXPECT_EQ(le.emitted(le.ray.dir), le.radiance);
    }
    if (le.infinite) {
      // Rays from infinity start outside the scene's bounding sphere, heading in.
      EXPECT_GE(length(le.ray.origin - scene.bounds().center()), r * 0.999f);
      EXPECT_LT(dot(le.ray.origin - scene.bounds().center(), le.ray.dir), 0);
    }
    ++checked;
  }
  EXPECT_GT(checked, 3500);
}

}  // namespace
}  // namespace tessera
