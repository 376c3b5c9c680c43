// Statistical tests of light transport in participating media with the path tracer: the white furnace (a medium that
// does not absorb vanishes under a uniform sky), Beer–Lambert attenuation by the medium around the objects, agreement
// of independent estimators (phase-function sampling alone against next-event estimation alone, through `interface`
// and `dielectric` boundaries and with a chromatic medium), the separate depth limit of media, and the scene
// documents' media refused where they are wrong.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "renderer/job.h"
#include "renderer/scene_error.h"
#include "renderer/session.h"
#include "tests/renderer/test_util.h"

namespace tessera {
namespace {

using nlohmann::json;

using test::render_document;

RenderSettings settings(int size, uint32_t spp, Estimator e, uint64_t seed, int max_depth = 16) {
  RenderSettings s;
  s.width = s.height = size;
  s.spp = spp;
  s.seed = seed;
  s.integrator.estimator = e;
  s.integrator.max_depth = max_depth;
  s.tile_size = 16;
  return s;
}

// The mean of each channel over the whole image.
Rgb mean_color(const std::vector<float>& rgb) {
  double sum[3] = {0, 0, 0};
  for (size_t i = 0; i < rgb.size(); i += 3)
    for (int c = 0; c < 3; ++c) sum[c] += rgb[i + c];
  const double n = static_cast<double>(rgb.size() / 3);
  return Rgb(static_cast<float>(sum[0] / n), static_cast<float>(sum[1] / n), static_cast<float>(sum[2] / n));
}

// A sphere of medium behind an `interface` boundary, filling the view, under a uniform white sky.
json furnace_scene(const json& medium) {
  return {
      {"materials", {{"boundary", {{"type", "interface"}}}}},
      {"objects", json::array({{{"shape", "sphere"},
                                {"center", {0, 0, 0}},
                                {"radius", 1},
                                {"material", "boundary"},
                                {"medium", medium}}})},
      {"camera", {{"from", {0, 0, 2.2}}, {"to", {0, 0, 0}}, {"fov_deg", 40}}},
      {"environment", {{"color", 1.0}}},
  };
}

// The white furnace (a closed form: with sigma_a = 0 every path leaves the sphere with its radiance unchanged, so
// the image is the sky's radiance 1 everywhere): for grey and chromatic media, isotropic and anisotropic, with each
// estimator (BSDF/phase sampling only, light sampling only, and MIS; the environment is the light). Medium
// scatterings and interface crossings are not bounces: max_depth 0 still lets every path through.
TEST(Media, WhiteFurnaceVanishes) {
  const json media[] = {
      {{"sigma_a", 0}, {"sigma_s", 1.5}, {"g", 0}},
      {{"sigma_s", {0.3, 1.2, 3.0}}, {"g", 0.6}},
      {{"sigma_s", 6.0}, {"g", -0.3}},
  };
  const Estimator estimators[] = {Estimator::kHemisphere, Estimator::kArea, Estimator::kMis};
  for (const json& medium : media) {
    for (Estimator e : estimators) {
      const Rgb mean = mean_color(render_document(furnace_scene(medium), settings(24, 1024, e, 3, 0)));
      std::printf("%s %s: %.4f %.4f %.4f\n", medium.dump().c_str(), estimator_name(e), mean.x, mean.y, mean.z);
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(mean[c], 1.0, 0.005) << medium.dump() << ", " << estimator_name(e) << ", channel " << c;
    }
  }
}

// The white furnace for every integrator. Under the uniform sky, path and bdpt: bdpt's camera subpaths scatter in the
// medium, its light subpaths come in from the sky, and every strategy that joins them crosses the interface. Light
// tracing does not see a light at infinity (bidirectional's header): its furnace is a uniformly emitting sphere
// around the scene (radiance 1 inwards, scattering nothing), which every integrator sees as 1 through a medium that
// does not absorb. Each mean is within 0.5 % of 1. Light tracing's image mean, from paths that mostly miss the view,
// has a standard error of about 0.3 % at 16384 samples per pixel (three seeds: 0.9999, 0.9969, 1.0046): it takes four
// times as many.
TEST(Media, WhiteFurnaceVanishesForEveryIntegrator) {
  const json media[] = {
      {{"sigma_s", 1.5}, {"g", 0}},
      {{"sigma_s", {0.3, 1.2, 3.0}}, {"g", 0.6}},
  };
  json enclosed = furnace_scene(media[0]);
  enclosed.erase("environment");
  enclosed["materials"]["sky"] = {{"type", "emission"}, {"radiance", 1.0}};
  enclosed["objects"].push_back({{"shape", "sphere"}, {"center", {0, 0, 0}}, {"radius", 2.5}, {"material", "sky"}});
  struct Case {
    std::string integrator;
    json scene;
    uint32_t spp;
  };
  std::vector<Case> cases;
  for (const json& medium : media) cases.push_back({"bdpt", furnace_scene(medium), 1024});
  for (const json& medium : media) {
    json scene = enclosed;
    scene["objects"][0]["medium"] = medium;
    for (const char* integrator : {"path", "bdpt", "light"})
      cases.push_back({integrator, scene, std::string(integrator) == "light" ? 65536u : 1024u});
  }
  for (const Case& k : cases) {
    RenderSettings s = settings(24, k.spp, Estimator::kMis, 3, 8);
    s.integrator.name = k.integrator;
    const Rgb mean = mean_color(render_document(k.scene, s));
    const std::string what = k.integrator + " " + k.scene["objects"][0]["medium"].dump() +
                             (k.scene.contains("environment") ? " under the sky" : " in the emitting sphere");
    std::printf("%s: %.4f %.4f %.4f\n", what.c_str(), mean.x, mean.y, mean.z);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(mean[c], 1.0, 0.005) << what << ", channel " << c;
  }
}

// The separate limit: with max_volume_depth 0 no path may cross the boundary, and the sphere is black.
TEST(Media, VolumeDepthLimitsCrossingsAndScattering) {
  RenderSettings s = settings(16, 16, Estimator::kMis, 5, 8);
  s.integrator.max_volume_depth = 0;
  const std::vector<float> img = render_document(furnace_scene({{"sigma_s", 1.0}}), s);
  const float* centre = &img[(8 * 16 + 8) * 3];
  EXPECT_EQ(centre[1], 0.0f);
}

// The medium around the objects (scene.medium): an emitting square seen head-on across a distance d of absorbing fog
// has radiance Le exp(-sigma_a d) (Beer–Lambert), and the sky, infinitely far, is not seen through it.
TEST(Media, SceneMediumAttenuatesAndHidesTheSky) {
  const float d = 3.0f;
  const json scene = {
      {"materials", {{"light", {{"type", "emission"}, {"radiance", 2.0}}}}},
      {"objects", json::array({{{"shape", "rectangle"},
                                {"corner", {-10, -10, -d}},
                                {"edge1", {20, 0, 0}},
                                {"edge2", {0, 20, 0}},
                                {"material", "light"}}})},
      {"camera", {{"from", {0, 0, 0}}, {"to", {0, 0, -1}}, {"fov_deg", 20}}},
      {"environment", {{"color", 1.0}}},
      {"medium", {{"sigma_a", {0.1, 0.3, 0.0}}}},
  };
  const Rgb mean = mean_color(render_document(scene, settings(8, 4, Estimator::kMis, 1)));
  // The square is head-on, the pixels' rays slightly oblique: at most 20/2 degrees off, a path 1.5 % longer.
  EXPECT_NEAR(mean.x, 2 * std::exp(-0.1 * d), 0.01);
  EXPECT_NEAR(mean.y, 2 * std::exp(-0.3 * d), 0.01);
  EXPECT_NEAR(mean.z, 2.0, 1e-5);
  json sky_only = scene;
  sky_only["camera"]["to"] = {0, 0, 1};
  EXPECT_TRUE(load_scene(sky_only, "/scene", SceneLoadOptions{})->warnings.empty());
  const Rgb sky = mean_color(render_document(sky_only, settings(8, 4, Estimator::kMis, 1)));
  EXPECT_EQ(sky.x, 0.0f);
  EXPECT_EQ(sky.y, 0.0f);
  EXPECT_NEAR(sky.z, 1.0, 1e-5);  // the channel the fog does not absorb
  // A fog that takes every channel hides the sky entirely, and the scene says so.
  sky_only["medium"]["sigma_a"] = 0.01;
  EXPECT_FALSE(load_scene(sky_only, "/scene", SceneLoadOptions{})->warnings.empty());
}

// Region means of K independent renders and their standard errors.
test::RegionStats estimate(const json& scene, Estimator e, int size, int regions, int runs, uint32_t spp) {
  return test::grid_region_stats(runs, size, regions, [&](int k) {
    return render_document(scene, settings(size, spp, e, 500 + 7919 * k + 104729 * static_cast<uint64_t>(e), 16));
  });
}

// Two independent estimators of a scene with a chromatic, absorbing, anisotropic medium behind an interface and
// another behind glass, lit by a spherical area light and a dim sky: phase/BSDF sampling alone (light found by hitting
// it) and next-event estimation alone (transmittance to the light through the medium and across the interface) agree
// within their standard errors, region by region and channel by channel; MIS agrees with both.
TEST(Media, EstimatorsAgreeOnScatteringSpheres) {
  const json scene = {
      {"materials",
       {{"boundary", {{"type", "interface"}}},
        {"glass", {{"type", "dielectric"}, {"ior", 1.33}}},
        {"floor", {{"type", "lambert"}, {"albedo", 0.5}}},
        {"lamp", {{"type", "emission"}, {"radiance", 6}}}}},
      {"objects", json::array({{{"shape", "sphere"},
                                {"center", {-0.6, 0, 0}},
                                {"radius", 0.55},
                                {"material", "boundary"},
                                {"medium", {{"sigma_a", {0.2, 0.1, 0.6}}, {"sigma_s", {2.0, 1.0, 3.0}}, {"g", 0.4}}}},
                               {{"shape", "sphere"},
                                {"center", {0.6, 0, 0}},
                                {"radius", 0.55},
                                {"material", "glass"},
                                {"medium", {{"sigma_s", 1.5}, {"sigma_a", 0.1}}}},
                               {{"shape", "rectangle"},
                                {"corner", {-3, -0.55, 3}},
                                {"edge1", {6, 0, 0}},
                                {"edge2", {0, 0, -6}},
                                {"material", "floor"}},
                               {{"shape", "sphere"}, {"center", {0, 2.2, 1}}, {"radius", 0.6}, {"material", "lamp"}}})},
      {"camera", {{"from", {0, 0.4, 3}}, {"to", {0, 0, 0}}, {"fov_deg", 45}}},
      {"environment", {{"color", 0.1}}},
  };
  const int size = 32, regions = 4, runs = 24;
  const uint32_t spp = 16;
  // 3 pairs x 16 regions x 3 channels = 144 comparisons with 23 degrees of freedom each: Bonferroni at a 0.1 %
  // family-wise false alarm rate asks for two-sided p < 7e-6 each, |t_23| < 5.8.
  const double bound = 5.8;
  const test::RegionStats hemisphere = estimate(scene, Estimator::kHemisphere, size, regions, runs, spp);
  const test::RegionStats area = estimate(scene, Estimator::kArea, size, regions, runs, spp);
  const test::RegionStats mis = estimate(scene, Estimator::kMis, size, regions, runs, spp);
  const double z_ha = test::worst_z(hemisphere, area), z_hm = test::worst_z(hemisphere, mis),
               z_am = test::worst_z(area, mis);
  std::printf("worst |z|: hemisphere vs area %.2f, hemisphere vs mis %.2f, area vs mis %.2f\n", z_ha, z_hm, z_am);
  EXPECT_LT(z_ha, bound);
  EXPECT_LT(z_hm, bound);
  EXPECT_LT(z_am, bound);
  // The comparison has the power to see a small bias: the same estimates with 5 % more light in one are rejected.
  EXPECT_GT(test::worst_z(area, mis, 1.05), bound);
}

// Bad media are refused naming the field, as a 422 names it.
TEST(Media, BadInputNamesTheField) {
  const json good = furnace_scene({{"sigma_a", 0.1}, {"sigma_s", 1.0}, {"g", 0.2}});
  EXPECT_NO_THROW(load_scene(good, "/scene", SceneLoadOptions{}));
  json bad = good;
  bad["objects"][0]["medium"]["sigma_a"] = -0.1;
  test::expect_scene_error(bad, "/scene/objects/0/medium/sigma_a");
  bad = good;
  bad["objects"][0]["medium"]["sigma_s"] = {1, -2, 1};
  test::expect_scene_error(bad, "/scene/objects/0/medium/sigma_s/1");
  for (double g : {1.0, -1.0, 1.5}) {
    bad = good;
    bad["objects"][0]["medium"]["g"] = g;
    test::expect_scene_error(bad, "/scene/objects/0/medium/g", "between -1 and 1");
  }
  bad = good;
  bad["objects"][0]["medium"]["sigma_t"] = 1;
  test::expect_scene_error(bad, "/scene/objects/0/medium/sigma_t");
  bad = good;
  bad["objects"][0]["medium"] = 3;
  test::expect_scene_error(bad, "/scene/objects/0/medium");
  bad = good;
  bad["objects"][0] = {{"shape", "rectangle"}, {"corner", {0, 0, 0}},    {"edge1", {1, 0, 0}},
                       {"edge2", {0, 1, 0}},   {"material", "boundary"}, {"medium", {{"sigma_s", 1}}}};
  test::expect_scene_error(bad, "/scene/objects/0/medium", "rectangle");
  bad = good;
  bad["materials"]["boundary"] = {{"type", "dielectric"}, {"attenuation_color", {0.5, 0.5, 0.5}}};
  test::expect_scene_error(bad, "/scene/objects/0/medium", "attenuation");
  bad = good;
  bad["materials"]["boundary"] = {{"type", "lambert"}};
  test::expect_scene_error(bad, "/scene/objects/0/material", "dielectric");
  bad = good;
  bad["medium"] = {{"g", -2}};
  test::expect_scene_error(bad, "/scene/medium/g");
  bad = good;
  bad["medium"] = {{"sigma_a", {0, 0, -1}}};
  test::expect_scene_error(bad, "/scene/medium/sigma_a/2");
  json job = {{"scene", good}, {"render", {{"max_volume_depth", -1}}}};
  try {
    load_job(job, JobLoadOptions{});
    ADD_FAILURE() << "a negative max_volume_depth was taken";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), "/render/max_volume_depth");
  }
}

}  // namespace
}  // namespace tessera
