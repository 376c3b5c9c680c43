// Light tracing and bidirectional path tracing against the path tracer and against closed forms: three estimators
// of one measurement (the measurement equation, Advanced Global Illumination, 2nd ed., 2.8) must agree within their own
// statistical errors, and both of the adjoint ones must keep the renderer's determinism (the same bits on any thread
// count, after a resume, and from merged parts).
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

#include "renderer/job.h"
#include "renderer/medium.h"
#include "renderer/scene_error.h"
#include "renderer/scene_loader.h"
#include "renderer/session.h"

namespace tessera {
namespace {

using nlohmann::json;

json cornell_scene() {
  std::ifstream in("proto/examples/cornell.json");
  if (!in) throw std::runtime_error("run the tests from the repository root (proto/examples/cornell.json)");
  return json::parse(in)["scene"];
}

RenderSettings settings(const std::string& integrator, int w, int h, uint32_t spp, uint64_t seed, int max_depth = 8) {
  RenderSettings s;
  s.width = w;
  s.height = h;
  s.spp = spp;
  s.seed = seed;
  s.integrator.name = integrator;
  s.integrator.max_depth = max_depth;
  s.tile_size = 16;
  return s;
}

std::vector<float> render(std::shared_ptr<const Scene> scene, const RenderSettings& s, int threads = 2) {
  ThreadPool pool(threads);
  RenderSession session(std::move(scene), s, pool);
  session.run();
  return session.film().resolve();
}

// Region means of K independent renders (seeds differ between runs and integrators) and their standard errors from
// the runs' spread: each integrator's error measured from its own samples. Per region and channel, or with
// `channels_together` one value per region: the mean of its three channels.
struct RegionStats {
  std::vector<double> mean, se;
};

// `regions` lists pixel rectangles {x, y, w, h}.
RegionStats region_stats(std::shared_ptr<const Scene> scene, const std::string& integrator, int w, int h,
                         const std::vector<PixelRegion>& regions, int runs, uint32_t spp, int max_depth = 8,
                         bool channels_together = false) {
  const size_t per_region = channels_together ? 1 : 3;
  std::vector<std::vector<double>> per_run(runs, std::vector<double>(regions.size() * per_region, 0));
  const uint64_t salt = std::hash<std::string>()(integrator) % 100003;
  for (int k = 0; k < runs; ++k) {
    const std::vector<float> img = render(scene, settings(integrator, w, h, spp, 1000 + 7919 * k + salt, max_depth));
    for (size_t r = 0; r < regions.size(); ++r) {
      const PixelRegion& g = regions[r];
      const double n = double(g.width) * g.height * double(3 / per_region);
      for (int y = g.y; y < g.y + g.height; ++y)
        for (int x = g.x; x < g.x + g.width; ++x)
          for (size_t c = 0; c < 3; ++c)
            per_run[k][r * per_region + c % per_region] += img[(static_cast<size_t>(y) * w + x) * 3 + c] / n;
    }
  }
  RegionStats s;
  for (size_t i = 0; i < per_run[0].size(); ++i) {
    double m = 0, v = 0;
    for (int k = 0; k < runs; ++k) m += per_run[k][i] / runs;
    for (int k = 0; k < runs; ++k) v += sqr(static_cast<float>(per_run[k][i] - m)) / (runs - 1);
    s.mean.push_back(m);
    s.se.push_back(std::sqrt(v / runs));
  }
  return s;
}

// A grid of n x n regions covering the image.
std::vector<PixelRegion> grid(int w, int h, int n) {
  std::vector<PixelRegion> out;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) out.push_back({i * w / n, j * h / n, w / n, h / n});
  return out;
}

// Largest |z| of the differences between two estimates, value by value.
double worst_z(const RegionStats& a, const RegionStats& b) {
  double worst = 0;
  for (size_t i = 0; i < a.mean.size(); ++i) {
    const double se = std::sqrt(sqr(static_cast<float>(a.se[i])) + sqr(static_cast<float>(b.se[i])));
    const double z = std::abs(a.mean[i] - b.mean[i]) / std::max(se, 1e-6 + 1e-4 * a.mean[i]);
    worst = std::max(worst, z);
  }
  return worst;
}

void print_stats(const char* name, const RegionStats& s) {
  std::printf("%-6s", name);
  for (size_t i = 0; i < s.mean.size(); ++i) std::printf(" %.6f(%.6f)", s.mean[i], s.se[i]);
  std::printf("\n");
}

// The three estimators agree on a scene: the region means of path and bdpt over `regions`, and of all three over
// `light_regions` (light tracing cannot see what only mirrors and glass show), differ by less than 3 standard errors
// (a z-test, each error measured from the estimator's own runs). The regions are few and large and their channels
// are taken together, so that a test makes 12 comparisons (4 regions, 3 pairs): with 32 runs (t with 31 degrees of
// freedom, P(|t| > 3) = 0.0053) a correct renderer fails one with probability at most 12 x 0.0053 = 6 % over
// choices of seeds (Bonferroni's inequality: any of K events is at most as likely as the sum of theirs). The seeds are
// fixed, so each test's verdict is deterministic; a bias shows as a |z| that grows as the square root of the samples,
// while noise keeps it near 1 whatever the samples. With `per_channel` each region's channels are compared apart (where
// a scene's colours are what is tested): 36 comparisons, held to 3.5 standard errors (P(|t| > 3.5) = 0.0014 with 31
// degrees of freedom: at most 5 % false alarms the same way).
void expect_agreement(const char* what, std::shared_ptr<const Scene> scene, int w, int h,
                      const std::vector<PixelRegion>& regions, const std::vector<PixelRegion>& light_regions,
                      uint32_t spp, uint32_t light_spp, bool per_channel = false) {
  const int runs = 32;
  const double limit = per_channel ? 3.5 : 3;
  const auto stats = [&](const char* integrator, const std::vector<PixelRegion>& r, uint32_t n) {
    return region_stats(scene, integrator, w, h, r, runs, n, 8, !per_channel);
  };
  const RegionStats path = stats("path", regions, spp), bdpt = stats("bdpt", regions, spp);
  const RegionStats path_l = stats("path", light_regions, spp), light = stats("light", light_regions, light_spp),
                    bdpt_l = stats("bdpt", light_regions, spp);
  print_stats("path", path);
  print_stats("bdpt", bdpt);
  print_stats("path", path_l);
  print_stats("light", light);
  print_stats("bdpt", bdpt_l);
  const double z_pb = worst_z(path, bdpt), z_pl = worst_z(path_l, light), z_lb = worst_z(light, bdpt_l);
  std::printf("%s: worst |z| path-bdpt %.2f, path-light %.2f, light-bdpt %.2f\n", what, z_pb, z_pl, z_lb);
  EXPECT_LT(z_pb, limit) << what;
  EXPECT_LT(z_pl, limit) << what;
  EXPECT_LT(z_lb, limit) << what;
}

TEST(Bidirectional, AgreesWithThePathTracerOnTheCornellBox) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  expect_agreement("cornell", scene, 32, 32, grid(32, 32, 2), grid(32, 32, 2), 16, 16);
}

// In participating media (medium vertices on both subpaths, joins through the media's transmittance and across
// `interface` boundaries): the Cornell box in a fog that fills the space around the objects (scene.medium, which the
// camera and the light sit in), and the Cornell box with a sphere of a chromatic, anisotropic medium behind an
// `interface` boundary (its colours compared channel by channel).
TEST(Bidirectional, AgreesWithThePathTracerInAFoggedRoom) {
  json doc = cornell_scene();
  doc["medium"] = {{"sigma_a", 0.3}, {"sigma_s", {1.2, 1.5, 2.0}}, {"g", 0.5}};
  auto scene = load_scene(doc, "/scene", SceneLoadOptions{});
  expect_agreement("fogged room", scene, 32, 32, grid(32, 32, 2), grid(32, 32, 2), 16, 16);
}

TEST(Bidirectional, AgreesWithThePathTracerOnAScatteringSphere) {
  json doc = cornell_scene();
  doc["materials"]["boundary"] = {{"type", "interface"}};
  doc["objects"].push_back({{"shape", "sphere"},
                            {"center", {0.28, 0.4, 0.15}},
                            {"radius", 0.1},
                            {"material", "boundary"},
                            {"medium", {{"sigma_a", {1, 2, 4}}, {"sigma_s", {20, 10, 15}}, {"g", 0.4}}}});
  auto scene = load_scene(doc, "/scene", SceneLoadOptions{});
  // The sphere's four quarters in the image.
  const std::vector<PixelRegion> sphere = {{11, 6, 5, 5}, {16, 6, 5, 5}, {11, 11, 5, 5}, {16, 11, 5, 5}};
  expect_agreement("scattering sphere", scene, 32, 32, sphere, sphere, 16, 16, true);
}

// The image depends only on (seed, pixel, sample index) with splats too: one thread and many give the same bits, a
// render stopped and resumed from its film gives the bits of one that was not, and films of sample ranges merge
// into the film of all the samples.
TEST(Bidirectional, DeterministicOverThreadsResumesAndMerges) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  for (const char* name : {"light", "bdpt"}) {
    SCOPED_TRACE(name);
    const RenderSettings all = settings(name, 24, 20, 7, 5);
    ThreadPool one(1), many(4);
    RenderSession a(scene, all, one), b(scene, all, many);
    a.run();
    b.run();
    EXPECT_TRUE(a.film().sums() == b.film().sums());
    // A different seed gives a different image (the comparison could fail).
    RenderSession other(scene, settings(name, 24, 20, 7, 6), many);
    other.run();
    EXPECT_FALSE(a.film().sums() == other.film().sums());

    RenderSettings part = all;
    part.spp = 3;  // passes of 1 and 2 samples
    RenderSession first(scene, part, many);
    first.run();
    RenderSession resumed(scene, all, many);
    resumed.restore(first.film(), first.progress().pass, first.progress().elapsed_s);
    resumed.run();
    EXPECT_TRUE(resumed.film().sums() == a.film().sums());

    Film merged(24, 20);
    for (auto [first_sample, count] : {std::pair<uint32_t, uint32_t>{4, 3}, {0, 4}}) {
      RenderSettings range = all;
      range.first_sample = first_sample;
      range.spp = count;
      RenderSession r(scene, range, many);
      r.run();
      merged.merge(r.film());
    }
    EXPECT_TRUE(merged.sums() == a.film().sums());
    EXPECT_EQ(merged.resolve(), a.film().resolve());
  }
}

// A pinhole camera looking straight at a disc of uniform radiance L (one-sided, towards the camera): every pixel the
// disc covers measures L, whatever the pixel's place in the image (the measurement equation with the normalised W_e
// of a pinhole, Veach 1997, 4.5). A Lambertian floor of albedo rho under the disc, facing it at height h on its axis,
// has radiance rho E / pi there with the irradiance of a disc of radius r, E = pi L r^2 / (h^2 + r^2).
json disc_scene(float cam_x) {
  json positions = json::array(), indices = json::array();
  const int n = 96;
  const float r = 0.5f, h = 1.0f;
  for (float v : {0.0f, h, 0.0f}) positions.push_back(v);
  for (int i = 0; i < n; ++i) {
    const float a = 2 * kPi * i / n;
    for (float v : {r * std::cos(a), h, r * std::sin(a)}) positions.push_back(v);
  }
  for (int i = 0; i < n; ++i)
    for (int v : {0, 1 + i, 1 + (i + 1) % n}) indices.push_back(v);  // facing down (-y)
  return {
      {"materials",
       {{"disc", {{"type", "emission"}, {"radiance", 2.0}, {"one_sided", true}}},
        {"floor", {{"type", "lambert"}, {"albedo", 0.5}}}}},
      {"objects",
       json::array({{{"shape", "mesh"}, {"positions", positions}, {"indices", indices}, {"material", "disc"}},
                    {{"shape", "rectangle"},
                     {"corner", {-20, 0, 20}},
                     {"edge1", {40, 0, 0}},
                     {"edge2", {0, 0, -40}},
                     {"material", "floor"}}})},
      {"camera", {{"from", {cam_x, 0.3, 0}}, {"to", {cam_x, 1, 0}}, {"up", {0, 0, -1}}, {"fov_deg", 60}}},
  };
}

TEST(Bidirectional, PinholeSeesAUniformDiscAsItsRadiance) {
  // The camera under the disc looking up: the disc covers the image's middle.
  auto scene = load_scene(disc_scene(0), "/scene", SceneLoadOptions{});
  const int size = 32;
  // The disc's edge is 35.5 degrees off the axis: the pixels within 30 degrees across (the image's middle half, and
  // its centre and edges) are all disc; the corners, 39 degrees out, are not.
  const std::vector<PixelRegion> regions = {{8, 8, 8, 8},   {16, 8, 8, 8}, {8, 16, 8, 8},
                                            {16, 16, 8, 8}, {0, 12, 4, 8}, {28, 12, 4, 8}};
  for (const char* name : {"path", "light", "bdpt"}) {
    RegionStats s = region_stats(scene, name, size, size, regions, 16, 16, 1);
    for (size_t i = 0; i < s.mean.size(); ++i)
      EXPECT_NEAR(s.mean[i], 2.0, std::max(4 * s.se[i], 1e-4)) << name << " region " << i / 3;
  }
}

TEST(Bidirectional, FloorUnderADiscHasTheClosedFormRadiance) {
  // Looking down from beside the disc's axis at the floor under its centre: radiance
  // rho L r^2 / (h^2 + r^2) = 0.5 x 2 x 0.25 / 1.25 = 0.2 at the centre, within 0.6 % over the pixels measured.
  json doc = disc_scene(0);
  doc["camera"] = {{"from", {0.0, 0.9, 0.0}}, {"to", {0, 0, 0}}, {"up", {0, 0, -1}}, {"fov_deg", 10}};
  auto scene = load_scene(doc, "/scene", SceneLoadOptions{});
  const int size = 16;
  const std::vector<PixelRegion> centre = {{6, 6, 4, 4}};
  for (const char* name : {"path", "light", "bdpt"}) {
    RegionStats s = region_stats(scene, name, size, size, centre, 16, 64, 1);
    std::printf("%s %.5f (%.5f)\n", name, s.mean[0], s.se[0]);
    EXPECT_NEAR(s.mean[0], 0.2, 4 * s.se[0] + 0.002) << name;
  }
}

// Glass: a smooth glass ball holding an emitting ball (light leaves the glass once: radiance crossing into air is
// scaled by 1/eta^2, importance is not, and light paths are wrong by eta^2 without the adjoint), beside it a rough
// glass ball (joined through by every strategy), a light above making caustics on a diffuse floor. The lights are
// large enough for the path tracer to find through the glass by BSDF sampling alone (its errors measured over runs
// are trustworthy only when many samples find them).
json glass_scene() {
  return {
      {"materials",
       {{"floor", {{"type", "lambert"}, {"albedo", 0.6}}},
        {"glass", {{"type", "dielectric"}, {"ior", 1.5}}},
        {"frosted", {{"type", "dielectric"}, {"ior", 1.5}, {"roughness", 0.3}}},
        {"bulb", {{"type", "emission"}, {"radiance", 4.0}}},
        {"lamp", {{"type", "emission"}, {"radiance", 6.0}, {"one_sided", true}}}}},
      {"objects",
       json::array({{{"shape", "rectangle"},
                     {"corner", {-4, 0, 4}},
                     {"edge1", {8, 0, 0}},
                     {"edge2", {0, 0, -8}},
                     {"material", "floor"}},
                    {{"shape", "sphere"}, {"center", {-0.6, 0.5, 0}}, {"radius", 0.5}, {"material", "glass"}},
                    {{"shape", "sphere"}, {"center", {-0.6, 0.5, 0}}, {"radius", 0.3}, {"material", "bulb"}},
                    {{"shape", "sphere"}, {"center", {0.7, 0.4, -0.2}}, {"radius", 0.4}, {"material", "frosted"}},
                    {{"shape", "rectangle"},
                     {"corner", {-0.3, 2.5, -0.3}},
                     {"edge1", {0.6, 0, 0}},
                     {"edge2", {0, 0, 0.6}},
                     {"material", "lamp"}}})},
      {"camera", {{"from", {0, 2.2, 3.2}}, {"to", {0, 0.3, 0}}, {"fov_deg", 50}}},
  };
}

// A glossy metal ball and a plastic-like ball on a diffuse floor under an environment map (a sky brighter towards
// its top and a broad bright patch), seen from above so that the camera sees no sky: light tracing sees it all.
std::shared_ptr<Scene> glossy_environment_scene() {
  json doc = {
      {"materials",
       {{"floor", {{"type", "lambert"}, {"albedo", 0.5}}},
        {"metal", {{"type", "conductor"}, {"metal", "gold"}, {"roughness", 0.25}}},
        {"plastic", {{"type", "plastic"}, {"albedo", 0.4}, {"roughness", 0.15}}}}},
      {"objects",
       json::array({{{"shape", "rectangle"},
                     {"corner", {-6, 0, 6}},
                     {"edge1", {12, 0, 0}},
                     {"edge2", {0, 0, -12}},
                     {"material", "floor"}},
                    {{"shape", "sphere"}, {"center", {-0.6, 0.5, 0}}, {"radius", 0.5}, {"material", "metal"}},
                    {{"shape", "sphere"}, {"center", {0.6, 0.5, 0.2}}, {"radius", 0.5}, {"material", "plastic"}}})},
      {"camera", {{"from", {0, 3.5, 2.0}}, {"to", {0, 0.2, 0}}, {"fov_deg", 45}}},
  };
  SceneLoadOptions unbuilt;
  unbuilt.build = false;
  auto scene = load_scene(doc, "/scene", unbuilt);
  const int w = 64, h = 32;
  std::vector<float> rgb(static_cast<size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float sky = 0.3f + 0.7f * std::max(0.0f, 1 - y / 16.0f);
      const float patch = (x >= 20 && x < 30 && y >= 4 && y < 10) ? 8.0f : 0.0f;
      rgb[(static_cast<size_t>(y) * w + x) * 3 + 0] = sky + patch;
      rgb[(static_cast<size_t>(y) * w + x) * 3 + 1] = sky + 0.8f * patch;
      rgb[(static_cast<size_t>(y) * w + x) * 3 + 2] = 1.2f * sky + 0.5f * patch;
    }
  scene->environment.map = std::make_shared<EnvironmentMap>(w, h, rgb);
  scene->environment.color = Rgb(1);
  scene->environment.rotation_deg = 40;
  scene->finalize();
  return scene;
}

TEST(Bidirectional, AgreesWithThePathTracerThroughGlass) {
  auto scene = load_scene(glass_scene(), "/scene", SceneLoadOptions{});
  // Light tracing cannot see what is seen through smooth glass: its regions are floor the balls do not cover (the
  // image's bottom quarter, and beside the balls).
  expect_agreement("glass", scene, 32, 32, grid(32, 32, 2),
                   {{0, 24, 16, 8}, {16, 24, 16, 8}, {0, 12, 5, 12}, {26, 8, 6, 12}}, 32, 64);
}

// A prism of dispersive glass (dispersion 10, V_d = 2: exaggerated, so that the colours part by tens of degrees) under
// a long narrow lamp throws a spectrum on the floor beside it: light leaving through its base bends by 33 degrees at
// 650 nm and 64 degrees at 450 nm. The camera looks down on the spectrum from above. The lamp is large enough for the
// path tracer to find through the prism by BSDF sampling.
json prism_scene() {
  // A triangular bar along z, apex up: base from x = -0.5 to 0.5 at height 1, apex at height 1 + sqrt(3)/2.
  const float h = 1.866f;
  const json positions = {-0.5, 1, -1, 0.5, 1, -1, 0, h, -1, -0.5, 1, 1, 0.5, 1, 1, 0, h, 1};
  const json indices = {0, 2, 1, 3, 4, 5, 0, 1, 4, 0, 4, 3, 1, 2, 5, 1, 5, 4, 2, 0, 3, 2, 3, 5};
  return {
      {"materials",
       {{"floor", {{"type", "lambert"}, {"albedo", 0.8}}},
        {"glass", {{"type", "dielectric"}, {"ior", 1.5}, {"dispersion", 10}}},
        {"lamp", {{"type", "emission"}, {"radiance", 20.0}, {"one_sided", true}}}}},
      {"objects",
       json::array({{{"shape", "rectangle"},
                     {"corner", {-4, 0, 4}},
                     {"edge1", {8, 0, 0}},
                     {"edge2", {0, 0, -8}},
                     {"material", "floor"}},
                    {{"shape", "mesh"}, {"positions", positions}, {"indices", indices}, {"material", "glass"}},
                    {{"shape", "rectangle"},
                     {"corner", {-0.2, 3.5, -1}},
                     {"edge1", {0.4, 0, 0}},
                     {"edge2", {0, 0, 2}},
                     {"material", "lamp"}}})},
      {"camera", {{"from", {-1.2, 4.5, 0}}, {"to", {-1.2, 0, 0}}, {"up", {0, 0, -1}}, {"fov_deg", 40}}},
  };
}

// Through dispersive glass every strategy that makes a path through it weights it by the path's wavelength, once, so
// the three estimators agree colour by colour on the prism's spectrum (from blue at the image's left to yellow beside
// the prism, whose top face fills the right edge): a strategy left unweighted would draw its part of the spectrum
// white.
TEST(Bidirectional, AgreesWithThePathTracerOnADispersivePrismsSpectrum) {
  auto scene = load_scene(prism_scene(), "/scene", SceneLoadOptions{});
  // Light tracing cannot see the floor through the prism: its regions stop short of it.
  expect_agreement("prism", scene, 32, 32, {{0, 8, 8, 16}, {8, 8, 8, 16}, {16, 8, 8, 16}, {24, 8, 8, 16}},
                   {{0, 8, 8, 16}, {8, 8, 8, 16}, {16, 8, 6, 16}, {0, 0, 22, 8}}, 32, 32, true);
}

TEST(Bidirectional, AgreesWithThePathTracerUnderAnEnvironmentMap) {
  auto scene = glossy_environment_scene();
  expect_agreement("environment", scene, 32, 32, grid(32, 32, 2), grid(32, 32, 2), 16, 16);
}

// The registry, the contract's enum and the job loader agree on the integrators; light and bdpt refuse a camera
// without importance (orthographic) at the field that chose them, before anything renders.
TEST(Bidirectional, RegisteredNamedInTheContractAndRefusedWithoutAPerspectiveCamera) {
  std::ifstream in("proto/schemas/render.schema.json");
  ASSERT_TRUE(in) << "run the tests from the repository root";
  const json schema = json::parse(in);
  std::vector<std::string> names = schema["properties"]["integrator"]["enum"];
  EXPECT_EQ(names, IntegratorRegistry::builtin().names());
  json job = {{"kind", "scene"}, {"scene", cornell_scene()}, {"render", {{"integrator", "bdpt"}, {"spp", 1}}}};
  EXPECT_EQ(load_job(job, JobLoadOptions{}).settings.integrator.name, "bdpt");
  job["scene"]["camera"]["type"] = "orthographic";
  for (const char* name : {"light", "bdpt"}) {
    job["render"]["integrator"] = name;
    try {
      load_job(job, JobLoadOptions{});
      ADD_FAILURE() << name << " accepted an orthographic camera";
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), "/render/integrator");
    }
  }
  job["render"]["integrator"] = "path";
  EXPECT_NO_THROW(load_job(job, JobLoadOptions{}));
}

// A sphere of index-matched glass (ior 1: no refraction, no reflection to speak of) whose inside absorbs, seen head-on
// against a white environment: the ray through its centre crosses one diameter of the medium, so the centre pixel is
// the colour white light turns after the attenuation distance, exp(-sigma_a d) with d the diameter (Beer-Lambert).
// Each integrator follows the medium from the surface it enters by to the one it leaves by (medium.h).
TEST(Media, AnAbsorbingSphereTransmitsTheBeerLambertFraction) {
  const json doc = {
      {"materials",
       {{"tinted",
         {{"type", "dielectric"},
          {"ior", 1.0},
          {"attenuation_color", {0.8, 0.5, 0.25}},
          {"attenuation_distance", 1.0}}}}},
      {"objects", json::array({{{"shape", "sphere"}, {"center", {0, 0, 0}}, {"radius", 0.5}, {"material", "tinted"}}})},
      {"camera", {{"from", {0, 0, 10}}, {"to", {0, 0, 0}}, {"fov_deg", 1}}},
      {"environment", {{"color", {1, 1, 1}}}},
  };
  auto scene = load_scene(doc, "/scene", SceneLoadOptions{});
  for (const std::string integrator : {"path", "bdpt"}) {
    // 9x9 pixels over 0.17 scene units: the centre pixel's rays cross chords within 0.04 % of the diameter.
    const std::vector<float> img = render(scene, settings(integrator, 9, 9, 4, 1));
    const size_t centre = (4 * 9 + 4) * 3;
    const float want[3] = {0.8f, 0.5f, 0.25f};
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(img[centre + c], want[c], 2e-3 * want[c]) << integrator << " channel " << c;
  }
}

// The attenuation parameters' medium: white light is `color` after `distance`, and after two distances its square
// (transmittance multiplies over segments); no positive distance, no medium; a black channel absorbs finitely.
TEST(Media, AnAttenuationColourIsWhatWhiteLightTurnsAfterItsDistance) {
  const double color[3] = {0.8, 0.5, 0.0};
  const auto medium = absorbing_medium(color, 2.0);
  ASSERT_TRUE(medium);
  const Rgb one = medium->transmittance(2.0f), two = medium->transmittance(4.0f);
  EXPECT_NEAR(one.x, 0.8f, 1e-6);
  EXPECT_NEAR(one.y, 0.5f, 1e-6);
  EXPECT_NEAR(one.z, 1e-6f, 1e-9);
  EXPECT_NEAR(two.x, 0.64f, 1e-6);
  EXPECT_NEAR(two.y, 0.25f, 1e-6);
  EXPECT_FALSE(absorbing_medium(color, 0.0));
  EXPECT_FALSE(absorbing_medium(color, -1.0));
  // The tracker: in by a front face, out by a back face; a direction not normalised counts its length.
  MediumTracker tracker;
  MediumRng rng;
  Rgb throughput(1);
  const Ray ray{Vec3(0, 0, 0), Vec3(0, 0, 2)};
  tracker.attenuate(throughput, ray, 1.0f, rng);
  EXPECT_EQ(throughput.x, 1.0f);  // vacuum
  tracker.refract(true, medium.get());
  tracker.attenuate(throughput, ray, 1.0f, rng);  // 2 units
  EXPECT_NEAR(throughput.x, 0.8f, 1e-6);
  tracker.refract(false, medium.get());
  EXPECT_EQ(tracker.current(), nullptr);
}

}  // namespace
}  // namespace tessera
