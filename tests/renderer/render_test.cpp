// Statistical tests of the light transport: closed forms (an emitting enclosure, the white furnace), agreement of
// the three independent estimators, and determinism.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <fstream>

#include "renderer/job.h"
#include "renderer/scene_error.h"
#include "renderer/session.h"
#include "tests/renderer/test_util.h"

namespace tessera {
namespace {

using nlohmann::json;

const Estimator kEstimators[] = {Estimator::kHemisphere, Estimator::kArea, Estimator::kMis};

struct Image {
  int width = 0, height = 0;
  std::vector<float> rgb;
  double mean_luminance() const {
    double s = 0;
    for (size_t i = 0; i < rgb.size(); i += 3) s += luminance(Rgb(rgb[i], rgb[i + 1], rgb[i + 2]));
    return s / (rgb.size() / 3);
  }
};

Image render(const json& scene_doc, RenderSettings settings, int threads = 0) {
  auto scene = load_scene(scene_doc, "/scene", SceneLoadOptions{});
  ThreadPool pool(threads);
  RenderSession session(scene, settings, pool);
  session.run();
  return {settings.width, settings.height, session.film().resolve()};
}

RenderSettings settings(int w, int h, uint32_t spp, Estimator e, uint64_t seed = 1, int max_depth = 8) {
  RenderSettings s;
  s.width = w;
  s.height = h;
  s.spp = spp;
  s.seed = seed;
  s.integrator.estimator = e;
  s.integrator.max_depth = max_depth;
  s.tile_size = 16;
  return s;
}

json cornell_scene() {
  std::ifstream in("proto/examples/cornell.json");
  if (!in) throw std::runtime_error("run the tests from the repository root (proto/examples/cornell.json)");
  return json::parse(in)["scene"];
}

// Inside a closed sphere whose surface has albedo rho and emits Le, the radiance is Le / (1 - rho) everywhere
// (the Neumann series of the rendering equation, Dutré et al., Advanced Global Illumination, 2nd ed., §2.6, summed in
// closed form): 0.5 / (1 - 0.5) = 1.
TEST(Transport, ClosedEmittingSphereHasRadianceOne) {
  json scene = {
      {"materials", {{"shell", {{"type", "lambert"}, {"albedo", 0.5}, {"emission", 0.5}}}}},
      {"objects", json::array({{{"shape", "sphere"}, {"center", {0, 0, 0}}, {"radius", 1}, {"material", "shell"}}})},
      {"camera", {{"from", {0, 0, 0.2}}, {"to", {0, 0, -1}}, {"fov_deg", 70}}},
  };
  for (Estimator e : kEstimators) {
    Image img = render(scene, settings(32, 32, 64, e, 3, 64));
    EXPECT_NEAR(img.mean_luminance(), 1.0, 0.025) << estimator_name(e);
  }
}

// A white Lambert sphere under a uniform white sky vanishes: every path returns exactly the sky radiance.
TEST(Transport, WhiteFurnace) {
  json scene = {
      {"materials", {{"white", {{"type", "lambert"}, {"albedo", 1.0}}}}},
      {"objects", json::array({{{"shape", "sphere"}, {"center", {0, 0, 0}}, {"radius", 1}, {"material", "white"}}})},
      {"camera", {{"from", {0, 0, 3}}, {"to", {0, 0, 0}}, {"fov_deg", 40}}},
      {"environment", {{"color", 1.0}}},
  };
  for (Estimator e : kEstimators) {
    Image img = render(scene, settings(32, 32, 64, e, 5, 32));
    // Only pixels on the sphere carry information; check them and the image.
    double on_sphere = 0;
    int n = 0;
    for (int y = 8; y < 24; ++y)
      for (int x = 8; x < 24; ++x) {
        const float* p = &img.rgb[(y * 32 + x) * 3];
        on_sphere += luminance(Rgb(p[0], p[1], p[2]));
        ++n;
      }
    EXPECT_NEAR(on_sphere / n, 1.0, 0.01) << estimator_name(e);
    EXPECT_NEAR(img.mean_luminance(), 1.0, 0.01) << estimator_name(e);
  }
}

// Dispersion keeps energy and colour: smooth glass that does not absorb vanishes under a uniform white sky whatever its
// index, so a dispersive smooth glass ball must too, channel by channel. Each path through the glass carries one
// wavelength and the weight w(lambda) / p(lambda) of renderer/spectrum.h, whose expectation is 1 in every channel:
// weights that were not (say, w without the division by p) tint the ball. The path tracer with each estimator, and
// bidirectional path tracing.
// A rough ball beside it loses light (its microfacets scatter once), and loses more where its index is higher, at the
// blue end: its colour is no closed form, but independent estimators must agree on it channel by channel (BSDF
// sampling alone, with light sampling by MIS through the dispersive BSDF's eval and pdf, and bidirectional).
TEST(Transport, DispersiveGlassVanishesInTheWhiteFurnace) {
  const json scene = {
      {"materials",
       {{"prism", {{"type", "dielectric"}, {"ior", 1.6}, {"dispersion", 3}}},
        {"frosted", {{"type", "dielectric"}, {"ior", 1.6}, {"dispersion", 3}, {"roughness", 0.3}}}}},
      {"objects",
       json::array({{{"shape", "sphere"}, {"center", {-1.05, 0, 0}}, {"radius", 1}, {"material", "prism"}},
                    {{"shape", "sphere"}, {"center", {1.05, 0, 0}}, {"radius", 1}, {"material", "frosted"}}})},
      {"camera", {{"from", {0, 0, 6}}, {"to", {0, 0, 0}}, {"fov_deg", 25}}},
      {"environment", {{"color", 1.0}}},
  };
  // The mean colour of the pixels well inside each ball's disc (centres at 1/4 and 3/4 of the width).
  auto balls = [](const Image& img) {
    std::array<Vec3, 2> mean;
    for (int ball = 0; ball < 2; ++ball) {
      Vec3 sum(0);
      int n = 0;
      const int cx = ball == 0 ? 16 : 48, cy = 16;
      for (int y = cy - 6; y <= cy + 6; ++y)
        for (int x = cx - 6; x <= cx + 6; ++x) {
          const float* p = &img.rgb[(y * 64 + x) * 3];
          sum += Rgb(p[0], p[1], p[2]);
          ++n;
        }
      mean[ball] = sum / static_cast<float>(n);
    }
    return mean;
  };
  RenderSettings bdpt = settings(64, 32, 128, Estimator::kMis, 13, 32);
  bdpt.integrator.name = "bdpt";
  for (Estimator e : kEstimators) {
    const std::array<Vec3, 2> b = balls(render(scene, settings(64, 32, 128, e, 11, 32)));
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(b[0][c], 1.0, 0.01) << estimator_name(e) << ", channel " << c;
  }
  const std::array<Vec3, 2> b = balls(render(scene, bdpt));
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(b[0][c], 1.0, 0.01) << "bdpt, channel " << c;

  bdpt.spp = 512;
  const Vec3 rough[3] = {balls(render(scene, settings(64, 32, 512, Estimator::kHemisphere, 17, 32)))[1],
                         balls(render(scene, settings(64, 32, 512, Estimator::kMis, 19, 32)))[1],
                         balls(render(scene, bdpt))[1]};
  std::printf(
      "rough dispersive ball, red green blue: hemisphere %.4f %.4f %.4f, mis %.4f %.4f %.4f, bdpt %.4f %.4f %.4f\n",
      rough[0].x, rough[0].y, rough[0].z, rough[1].x, rough[1].y, rough[1].z, rough[2].x, rough[2].y, rough[2].z);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(rough[1][c], rough[0][c], 0.015) << "mis against hemisphere, channel " << c;
    EXPECT_NEAR(rough[2][c], rough[0][c], 0.015) << "bdpt against hemisphere, channel " << c;
  }
}

// A furnace with absorption: a grey sphere of albedo 0.5 under a white sky. Each bounce off a convex object escapes,
// so radiance off the sphere is exactly albedo * sky = 0.5: all estimators must find it.
TEST(Transport, GreyFurnaceOfConvexObject) {
  json scene = {
      {"materials", {{"grey", {{"type", "lambert"}, {"albedo", 0.5}}}}},
      {"objects", json::array({{{"shape", "sphere"}, {"center", {0, 0, 0}}, {"radius", 1}, {"material", "grey"}}})},
      {"camera", {{"from", {0, 0, 3}}, {"to", {0, 0, 0}}, {"fov_deg", 20}}},
      {"environment", {{"color", 1.0}}},
  };
  for (Estimator e : kEstimators) {
    Image img = render(scene, settings(16, 16, 256, e, 9, 8));
    double s = 0;
    for (int y = 4; y < 12; ++y)
      for (int x = 4; x < 12; ++x) s += img.rgb[(y * 16 + x) * 3 + 1];
    EXPECT_NEAR(s / 64, 0.5, 0.01) << estimator_name(e);
  }
}

// The hemisphere, area and MIS estimators are independent unbiased estimators of the same image: their region means
// must agree within their statistical error. Each estimator renders K independent images (different seeds); the
// spread of the region means across them gives the standard error.
test::RegionStats region_stats(const json& scene, Estimator e, int size, int regions, int runs, uint32_t spp) {
  return test::grid_region_stats(runs, size, regions, [&](int k) {
    // Seeds differ between estimators too, so that the three estimates are statistically independent.
    return render(scene, settings(size, size, spp, e, 1000 + 7919 * k + 104729 * static_cast<int>(e), 8)).rgb;
  });
}

TEST(Transport, EstimatorsAgreeOnTheCornellBox) {
  const json scene = cornell_scene();
  // 32 runs give the standard errors 31 degrees of freedom. 3 pairs x 16 regions x 3 channels = 144 comparisons;
  // Bonferroni at a 0.1% family-wise false alarm rate asks for two-sided p < 7e-6 each, i.e. |t_31| < 5.6.
  const int size = 48, regions = 4, runs = 32;
  const uint32_t spp = 8;
  const double bound = 5.6;
  std::vector<test::RegionStats> stats;
  for (Estimator e : kEstimators) stats.push_back(region_stats(scene, e, size, regions, runs, spp));
  for (int a = 0; a < 3; ++a)
    for (int b = a + 1; b < 3; ++b) {
      double z = test::worst_z(stats[a], stats[b]);
      std::printf("%s vs %s: worst |z| = %.2f\n", estimator_name(kEstimators[a]), estimator_name(kEstimators[b]), z);
      EXPECT_LT(z, bound) << estimator_name(kEstimators[a]) << " vs " << estimator_name(kEstimators[b]);
    }
  // The comparison has the power to see a small bias: the same estimates with 5% more light in one are rejected.
  EXPECT_GT(test::worst_z(stats[1], stats[2], 1.05), bound);
}

// Films of disjoint sample ranges merge into exactly the film of one render of all samples.
TEST(Determinism, MergedSampleRangesEqualOneRender) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  ThreadPool pool(2);
  RenderSettings all = settings(24, 24, 13, Estimator::kMis, 5);
  RenderSession whole(scene, all, pool);
  whole.run();
  Film merged(24, 24);
  for (auto [first, count] : {std::pair<uint32_t, uint32_t>{5, 8}, {0, 5}}) {  // merged out of order
    RenderSettings part = all;
    part.first_sample = first;
    part.spp = count;
    RenderSession s(scene, part, pool);
    s.run();
    merged.merge(s.film());
  }
  EXPECT_EQ(merged.samples(), 13u);
  EXPECT_TRUE(merged.sums() == whole.film().sums());
  EXPECT_EQ(merged.resolve(), whole.film().resolve());
}

// The image depends only on (seed, pixel, sample index): one thread and many give the same bits.
TEST(Determinism, SameImageOnOneThreadAndMany) {
  const json scene = cornell_scene();
  RenderSettings s = settings(40, 30, 8, Estimator::kMis, 11);
  Image one = render(scene, s, 1);
  Image many = render(scene, s, 4);
  ASSERT_EQ(one.rgb.size(), many.rgb.size());
  EXPECT_EQ(0, std::memcmp(one.rgb.data(), many.rgb.data(), one.rgb.size() * sizeof(float)));
  // A different seed gives a different image (the test could fail).
  Image other = render(scene, settings(40, 30, 8, Estimator::kMis, 12), 2);
  EXPECT_NE(0, std::memcmp(one.rgb.data(), other.rgb.data(), one.rgb.size() * sizeof(float)));
}

// Stopping after some passes and resuming from the film continues exactly where an uninterrupted render would be.
TEST(Determinism, ResumeFromFilmIsBitIdentical) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  ThreadPool pool(2);
  RenderSettings full = settings(32, 32, 12, Estimator::kMis, 21);
  RenderSession uninterrupted(scene, full, pool);
  uninterrupted.run();

  RenderSettings part = full;
  part.spp = 5;  // stops mid-way, after passes of 1, 2 and 2 samples
  RenderSession first(scene, part, pool);
  first.run();
  RenderSession resumed(scene, full, pool);
  resumed.restore(first.film(), first.progress().pass, first.progress().elapsed_s);
  resumed.run();
  EXPECT_EQ(resumed.film().samples(), 12u);
  EXPECT_TRUE(uninterrupted.film().sums() == resumed.film().sums());
  EXPECT_EQ(uninterrupted.film().resolve(), resumed.film().resolve());
}

TEST(Session, ReportsProgressAfterEveryPassAndHonoursCancel) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  ThreadPool pool(2);
  RenderSession session(scene, settings(32, 32, 1000, Estimator::kMis, 1), pool);
  std::vector<uint32_t> seen;
  StopReason r = session.run([&](const RenderProgress& p, const Film& film) {
    seen.push_back(p.samples_done);
    EXPECT_EQ(film.samples(), p.samples_done);
    if (seen.size() == 3) session.cancel();
  });
  EXPECT_EQ(r, StopReason::kCancelled);
  ASSERT_EQ(seen.size(), 3u);
  EXPECT_EQ(seen[0], 1u);  // the first preview comes after one sample
  EXPECT_LT(seen[0], seen[1]);
  EXPECT_LT(seen[1], seen[2]);
}

TEST(Session, TimeLimitAndNoiseTargetStopTheRender) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  ThreadPool pool(2);
  RenderSettings s = settings(32, 32, 1u << 16, Estimator::kMis, 1);
  s.time_limit_s = 0.3;
  RenderSession timed(scene, s, pool);
  EXPECT_EQ(timed.run(), StopReason::kTimeLimit);
  EXPECT_GE(timed.progress().elapsed_s, 0.3);
  EXPECT_LT(timed.progress().samples_done, s.spp);

  RenderSettings n = settings(32, 32, 1u << 16, Estimator::kMis, 1);
  n.noise_target = 0.05;
  RenderSession noisy(scene, n, pool);
  EXPECT_EQ(noisy.run(), StopReason::kNoiseTarget);
  EXPECT_LE(noisy.film().relative_error(), 0.05);
}

// Integrators are made by name through one registry; the job's render.integrator picks one, and a name the registry
// does not have is refused naming the field (and by a session given it directly).
TEST(Integrators, RegistryMakesThemByNameAndTheJobNamesOne) {
  const IntegratorRegistry& registry = IntegratorRegistry::builtin();
  EXPECT_TRUE(registry.has("path"));
  EXPECT_FALSE(registry.has("photon_mapping"));
  EXPECT_EQ(render_settings_from_json(json::object(), "/render", RenderLimits{}).integrator.name, "path");
  EXPECT_EQ(render_settings_from_json({{"integrator", "path"}}, "/render", RenderLimits{}).integrator.name, "path");
  for (const json& bad : {json("photon_mapping"), json(3)}) {
    try {
      render_settings_from_json({{"integrator", bad}}, "/render", RenderLimits{});
      ADD_FAILURE() << "accepted " << bad;
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), "/render/integrator");
      EXPECT_NE(std::string(e.what()).find("\"path\""), std::string::npos) << e.what();
    }
  }
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  ThreadPool pool(1);
  RenderSettings s = settings(8, 8, 1, Estimator::kMis);
  s.integrator.name = "photon_mapping";
  EXPECT_THROW(RenderSession(scene, s, pool), std::invalid_argument);
}

TEST(SceneLoading, ErrorsNameTheField) {
  json scene = cornell_scene();
  auto expect_error = [&](json doc, const std::string& pointer) {
    try {
      load_scene(doc, "/scene", SceneLoadOptions{});
      ADD_FAILURE() << "no error for " << pointer;
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), pointer) << e.what();
    }
  };
  json bad = scene;
  bad["objects"][0]["material"] = "nope";
  expect_error(bad, "/scene/objects/0/material");
  bad = scene;
  bad.erase("camera");
  expect_error(bad, "/scene/camera");
  bad = scene;
  bad["objects"][6]["indices"][4] = 1000;
  expect_error(bad, "/scene/objects/6/indices/4");
  bad = scene;
  bad["camera"]["fov_deg"] = 0;
  expect_error(bad, "/scene/camera/fov_deg");
  bad = scene;
  bad["materials"]["white"]["albedo"] = json::array({0.5, 2.0, 0.5});
  expect_error(bad, "/scene/materials/white/albedo/1");
  bad = scene;
  bad["materials"]["white"]["type"] = "velvet";
  expect_error(bad, "/scene/materials/white/type");
  bad = scene;
  bad["objects"][0]["shape"] = "torus";
  expect_error(bad, "/scene/objects/0/shape");
  // Integers are read exactly: 2^53 + 1, which a double reads as 2^53 (the seed's maximum), is beyond it.
  EXPECT_EQ(render_settings_from_json(json{{"seed", 9007199254740992ull}}, "/render", {}).seed, 9007199254740992ull);
  try {
    render_settings_from_json(json{{"seed", 9007199254740993ull}}, "/render", {});
    ADD_FAILURE() << "a seed of 2^53 + 1 was taken";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), "/render/seed") << e.what();
  }
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Estimators agree under a strongly non-uniform environment map (importance sampling of the map vs BSDF sampling):
// a grey sphere on a grey floor under a small bright "sun".
TEST(Transport, EstimatorsAgreeUnderAnEnvironmentMap) {
  const int w = 64, h = 32;
  std::vector<float> rgb(static_cast<size_t>(w) * h * 3, 0.3f);
  for (int y = 6; y < 9; ++y)
    for (int x = 36; x < 40; ++x)
      for (int c = 0; c < 3; ++c) rgb[(static_cast<size_t>(y) * w + x) * 3 + c] = 60.0f;
  auto map = std::make_shared<EnvironmentMap>(w, h, rgb);
  json doc = {
      {"materials", {{"grey", {{"type", "lambert"}, {"albedo", 0.6}}}}},
      {"objects", json::array({{{"shape", "sphere"}, {"center", {0, 1, 0}}, {"radius", 1}, {"material", "grey"}},
                               {{"shape", "rectangle"},
                                {"corner", {-4, 0, 4}},
                                {"edge1", {8, 0, 0}},
                                {"edge2", {0, 0, -8}},
                                {"material", "grey"}}})},
      {"camera", {{"from", {0, 2, 5}}, {"to", {0, 0.8, 0}}, {"fov_deg", 45}}},
  };
  const int size = 32, runs = 24;
  std::vector<std::vector<double>> means(3);
  std::vector<double> mean(3), se(3);
  for (int e = 0; e < 3; ++e) {
    for (int k = 0; k < runs; ++k) {
      SceneLoadOptions unbuilt;
      unbuilt.build = false;
      auto scene = load_scene(doc, "/scene", unbuilt);
      scene->environment.map = map;
      scene->environment.color = Rgb(1);
      scene->environment.rotation_deg = 30;
      scene->finalize();
      ThreadPool pool(2);
      RenderSession session(scene, settings(size, size, 8, kEstimators[e], 500 + 31 * k + 7777 * e, 6), pool);
      session.run();
      Image img{size, size, session.film().resolve()};
      means[e].push_back(img.mean_luminance());
    }
    for (double m : means[e]) mean[e] += m / runs;
    double v = 0;
    for (double m : means[e]) v += (m - mean[e]) * (m - mean[e]) / (runs - 1);
    se[e] = std::sqrt(v / runs);
  }
  for (int a = 0; a < 3; ++a)
    for (int b = a + 1; b < 3; ++b) {
      double z = std::abs(mean[a] - mean[b]) / std::sqrt(se[a] * se[a] + se[b] * se[b]);
      std::printf("env map: %s %.4f vs %s %.4f, z = %.2f\n", estimator_name(kEstimators[a]), mean[a],
                  estimator_name(kEstimators[b]), mean[b], z);
      EXPECT_LT(z, 4.5);
    }
  // Importance sampling the map pays: the light-sampling estimators are less noisy than BSDF sampling alone.
  EXPECT_LT(se[2], se[0]);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// At equal samples per pixel, the scrambled Sobol sampler is at least as accurate as independent sampling on the
// Cornell box (it is usually well ahead); broken decorrelation between dimensions would show as bias and lose.
TEST(Sampler, SobolIsNotWorseThanIndependentAtEqualSpp) {
  const json scene = cornell_scene();
  RenderSettings ref = settings(32, 32, 4096, Estimator::kMis, 4242);
  ref.sampler = SamplerKind::kIndependent;
  Image reference = render(scene, ref);
  double mse[2] = {0, 0};
  const int seeds = 4;
  for (int k = 0; k < 2; ++k)
    for (int seed = 0; seed < seeds; ++seed) {
      RenderSettings s = settings(32, 32, 16, Estimator::kMis, 10 + seed);
      s.sampler = k == 0 ? SamplerKind::kIndependent : SamplerKind::kSobol;
      Image img = render(scene, s);
      for (size_t i = 0; i < img.rgb.size(); ++i)
        mse[k] += sqr(img.rgb[i] - reference.rgb[i]) / (img.rgb.size() * seeds);
    }
  std::printf("Cornell 32x32 at 16 spp: RMSE independent %.5f, sobol %.5f (ratio %.2f)\n", std::sqrt(mse[0]),
              std::sqrt(mse[1]), std::sqrt(mse[1] / mse[0]));
  EXPECT_LT(mse[1], mse[0] * 1.05);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

TEST(MaterialJob, RendersTheStageAndNamesBadFieldsInTheJob) {
  JobLoadOptions opts;
  json job = {{"kind", "material"},
              {"material", {{"type", "lambert"}, {"albedo", {0.8, 0.2, 0.2}}}},
              {"render", {{"width", 48}, {"height", 32}, {"spp", 4}}}};
  RenderJob rj = load_job(job, opts);
  ThreadPool pool(2);
  RenderSession session(rj.scene, rj.settings, pool);
  session.run();
  double sum = 0;
  for (float v : session.film().resolve()) sum += v;
  EXPECT_GT(sum, 0);

  auto pointer_of = [&](const json& doc) {
    try {
      load_job(doc, opts);
    } catch (const SceneError& e) {
      return e.pointer();
    }
    return std::string("(accepted)");
  };
  json bad = job;
  bad["material"]["albedo"] = {0.5, 7, 0.5};
  EXPECT_EQ(pointer_of(bad), "/material/albedo/1");
  json row = {{"kind", "material"},
              {"materials", {{{"type", "lambert"}}, {{"type", "lambert"}, {"albedo", -1}}}},
              {"render", {{"width", 64}, {"height", 32}, {"spp", 1}}}};
  EXPECT_EQ(pointer_of(row), "/materials/1/albedo");
  row["materials"][1] = {{"type", "no_such_model"}};
  EXPECT_EQ(pointer_of(row), "/materials/1/type");
}

}  // namespace
}  // namespace tessera
