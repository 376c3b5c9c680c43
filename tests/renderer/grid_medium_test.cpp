// Media from OpenVDB grids (renderer/grid_medium.h): ratio tracking of a constant grid transmits exp(-sigma_t d) and
// of a linear gradient exp(-optical depth) in closed form; delta (spectral) tracking's weights are unbiased per
// channel; a box of a constant grid renders as the homogeneous medium of the same coefficients, within the renders'
// standard errors; and bad grids are refused naming the field, as a 422 names it. The grids are written here, with
// OpenVDB.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "renderer/grid_medium.h"
#include "renderer/job.h"
#include "renderer/scene_error.h"
#include "renderer/session.h"
#include "tests/renderer/test_util.h"
#include "tests/renderer/vdb_fixture.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

using test::kVoxel;
using test::make_grid;

// A folder of the test's grid files, removed at the end.
struct GridFolder {
  GridFolder() : path(fs::temp_directory_path() / ("tessera_grid_test_" + std::to_string(::getpid()))) {
    fs::create_directories(path);
  }
  ~GridFolder() { fs::remove_all(path); }
  // Writes `grids` to `name` in the folder; returns its path.
  fs::path write(const std::string& name, const openvdb::GridPtrVec& grids) const {
    test::write_vdb(path / name, grids);
    return path / name;
  }
  fs::path path;
};

GridMediumDesc desc_of(const fs::path& file, Rgb sigma_a, Rgb sigma_s) {
  GridMediumDesc d;
  d.file = file;
  d.sigma_a = sigma_a;
  d.sigma_s = sigma_s;
  return d;
}

// exp(-sigma_t tau) per channel: the transmittance over optical depth tau at unit density (Beer–Lambert).
Rgb beer(const Rgb& sigma_t, float tau) {
  return Rgb(std::exp(-sigma_t.x * tau), std::exp(-sigma_t.y * tau), std::exp(-sigma_t.z * tau));
}

// Mean and standard error of n draws of `estimate` (an Rgb each), per channel.
template <typename F>
std::pair<Rgb, Rgb> mean_and_se(int n, F estimate) {
  double sum[3] = {0, 0, 0}, sq[3] = {0, 0, 0};
  for (int i = 0; i < n; ++i) {
    const Rgb v = estimate(i);
    for (int c = 0; c < 3; ++c) {
      sum[c] += v[c];
      sq[c] += double(v[c]) * v[c];
    }
  }
  Rgb mean, se;
  for (int c = 0; c < 3; ++c) {
    const double m = sum[c] / n;
    mean[c] = static_cast<float>(m);
    se[c] = static_cast<float>(std::sqrt(std::max(0.0, sq[c] / n - m * m) / (n - 1)));
  }
  return {mean, se};
}

// Expects each channel of `mean` within 4 standard errors of `expected` (with a floor for channels that have no
// variance).
void expect_within(const std::pair<Rgb, Rgb>& estimate, const Rgb& expected, const std::string& what) {
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(estimate.first[c], expected[c], 4 * estimate.second[c] + 1e-5f)
        << what << ", channel " << c << " (standard error " << estimate.second[c] << ")";
}

TEST(MediumGrid, RatioTrackingOfAConstantGridIsExpOfMinusSigmaTD) {
  const GridFolder folder;
  const int n = 21;  // the constant box: [0, 1]^3
  const fs::path file = folder.write("constant.vdb", {make_grid(n, [](int, int, int) { return 1.0f; })});
  GridMediumDesc d = desc_of(file, Rgb(0.5f, 0.1f, 2.0f), Rgb(1.0f, 0.2f, 0.0f));
  d.density_scale = 0.8f;
  d.majorant_grid = false;  // one majorant: the grid of them is the gradient's test
  const auto medium = load_grid_medium(d);
  EXPECT_FALSE(medium->homogeneous());
  EXPECT_TRUE(medium->scatters());
  const Rgb sigma_t = (d.sigma_a + d.sigma_s) * d.density_scale;
  // Along the x axis through the box (a direction not of unit length: distances are along the unit direction), and
  // diagonally across it.
  const Ray along{Vec3(0.0f, 0.5f, 0.5f), Vec3(3, 0, 0)};
  const Ray diagonal{Vec3(0.1f, 0.2f, 0.3f), Vec3(0.6f, 0.5f, 0.4f)};
  for (const auto& [ray, distance] : {std::pair{along, 0.8f}, std::pair{diagonal, 1.0f}}) {
    MediumRng rng(7);
    const auto estimate = mean_and_se(20000, [&](int) { return medium->transmittance(ray, distance, rng); });
    const Rgb expected = beer(sigma_t, distance);
    std::printf("transmittance over %.2f: %.4f %.4f %.4f (expected %.4f %.4f %.4f, se %.4f %.4f %.4f)\n", distance,
                estimate.first.x, estimate.first.y, estimate.first.z, expected.x, expected.y, expected.z,
                estimate.second.x, estimate.second.y, estimate.second.z);
    expect_within(estimate, expected, "ratio tracking");
  }
}

// Spectral tracking's weights: over a segment of length d of a constant chromatic medium, the crossing's expected
// weight is exp(-sigma_t d) and the scattering's sigma_s / sigma_t (1 - exp(-sigma_t d)), per channel, whatever the
// path's throughput (which only sets the probabilities).
TEST(MediumGrid, DeltaTrackingWeightsAreUnbiasedPerChannel) {
  const GridFolder folder;
  const fs::path file = folder.write("constant.vdb", {make_grid(21, [](int, int, int) { return 1.0f; })});
  const GridMediumDesc d = desc_of(file, Rgb(0.3f, 0.0f, 1.0f), Rgb(1.5f, 0.4f, 2.0f));
  const auto medium = load_grid_medium(d);
  const Rgb sigma_t = d.sigma_a + d.sigma_s;
  const Ray ray{Vec3(0.05f, 0.5f, 0.5f), Vec3(1, 0, 0)};
  const float distance = 0.9f;
  for (const Rgb& throughput : {Rgb(1), Rgb(0.2f, 1.0f, 0.5f)}) {
    MediumRng rng(11);
    uint64_t draw = 0;
    const auto crossed = mean_and_se(40000, [&](int) {
      const FreeFlight f = medium->sample_free_flight(ray, distance, throughput, MediumRng(++draw).next(), rng);
      return f.scattered ? Rgb(0) : f.weight;
    });
    draw = 0;
    const auto scattered = mean_and_se(40000, [&](int) {
      const FreeFlight f = medium->sample_free_flight(ray, distance, throughput, MediumRng(++draw).next(), rng);
      EXPECT_TRUE(!f.scattered || (f.t >= 0 && f.t < distance));
      return f.scattered ? f.weight : Rgb(0);
    });
    Rgb expect_crossed, expect_scattered;
    for (int c = 0; c < 3; ++c) {
      expect_crossed[c] = std::exp(-sigma_t[c] * distance);
      expect_scattered[c] = d.sigma_s[c] / sigma_t[c] * (1 - expect_crossed[c]);
    }
    expect_within(crossed, expect_crossed, "crossing");
    expect_within(scattered, expect_scattered, "scattering");
  }
}

// A density growing linearly along x, rho(x) = 0.5 + 2 x (trilinear interpolation reproduces it exactly): along x
// from a to b the optical depth is sigma_t (0.5 (b - a) + (b^2 - a^2)); the grid placed by scale and translate
// moves it with it.
TEST(MediumGrid, RatioTrackingOfAGradientMatchesTheAnalyticOpticalDepth) {
  const GridFolder folder;
  const fs::path file =
      folder.write("gradient.vdb", {make_grid(21, [](int i, int, int) { return 0.5f + 2.0f * (i * kVoxel); })});
  for (const bool majorant_grid : {true, false}) {
    SCOPED_TRACE(majorant_grid ? "majorant grid" : "global majorant");
    GridMediumDesc d = desc_of(file, Rgb(0.4f, 1.0f, 0.0f), Rgb(0.6f, 0.0f, 0.3f));
    d.majorant_grid = majorant_grid;
    const auto medium = load_grid_medium(d);
    const Rgb sigma_t = d.sigma_a + d.sigma_s;
    const auto optical_depth = [](float a, float b) { return 0.5f * (b - a) + (b * b - a * a); };
    MediumRng rng(3);
    const auto estimate = mean_and_se(20000, [&](int) {
      return medium->transmittance(Ray{Vec3(0.1f, 0.5f, 0.5f), Vec3(1, 0, 0)}, 0.8f, rng);
    });
    const float tau = optical_depth(0.1f, 0.9f);
    expect_within(estimate, beer(sigma_t, tau), "gradient");
    // Backwards along the same stretch, the same.
    const auto back = mean_and_se(20000, [&](int) {
      return medium->transmittance(Ray{Vec3(0.9f, 0.5f, 0.5f), Vec3(-1, 0, 0)}, 0.8f, rng);
    });
    expect_within(back, beer(sigma_t, tau), "gradient backwards");
    // Placed at twice the size and 3 units along x: scene x = 2 x + 3, the density at scene x is rho((x - 3) / 2),
    // and the optical depth from scene 3.2 to 4.8 is twice that from 0.1 to 0.9. With the majorant grid (cells of 8
    // voxels along the gradient, each its own majorant) and with one majorant.
    d.scale = 2;
    d.translate = Vec3(3, 0, 0);
    const auto placed = load_grid_medium(d);
    const auto moved = mean_and_se(20000, [&](int) {
      return placed->transmittance(Ray{Vec3(3.2f, 1.0f, 1.0f), Vec3(1, 0, 0)}, 1.6f, rng);
    });
    expect_within(moved, beer(sigma_t, 2 * tau), "placed gradient");
  }
}

// The majorant grid's cells follow the density: across a step from 0.1 to 3 (at a leaf node's edge, between voxel
// centres 23 and 24, where interpolation ramps it linearly) the optical depth is the step's, forwards and backwards,
// with the grid of majorants and with one; and a grid whose density is an OpenVDB tile (a node's value, no voxels)
// is the constant it holds.
TEST(MediumGrid, TheMajorantGridFollowsStepsAndTiles) {
  const GridFolder folder;
  const float low = 0.1f, high = 3.0f;
  const fs::path step_file =
      folder.write("step.vdb", {make_grid(48, [&](int i, int, int) { return i >= 24 ? high : low; })});
  auto tiled = openvdb::FloatGrid::create(0.0f);
  tiled->setTransform(openvdb::math::Transform::createLinearTransform(kVoxel));
  tiled->setName("density");
  tiled->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(127)), 0.5f, true);
  ASSERT_GT(tiled->tree().activeTileCount(), 0u);
  const fs::path tile_file = folder.write("tiles.vdb", {tiled});
  const float a = 0.1f, b = 2.2f, up = 23 * kVoxel, to = 24 * kVoxel;
  const float tau = low * (up - a) + (low + high) / 2 * (to - up) + high * (b - to);
  for (const bool majorant_grid : {true, false}) {
    SCOPED_TRACE(majorant_grid ? "majorant grid" : "global majorant");
    GridMediumDesc d = desc_of(step_file, Rgb(0.2f, 0.5f, 0.0f), Rgb(0.3f, 0.0f, 0.1f));
    d.majorant_grid = majorant_grid;
    const auto step = load_grid_medium(d);
    const Rgb sigma_t = d.sigma_a + d.sigma_s;
    const Rgb expected = beer(sigma_t, tau);
    MediumRng rng(5);
    expect_within(mean_and_se(20000,
                              [&](int) {
                                return step->transmittance(Ray{Vec3(a, 1.0f, 1.1f), Vec3(1, 0, 0)}, b - a, rng);
                              }),
                  expected, "step forwards");
    expect_within(mean_and_se(20000,
                              [&](int) {
                                return step->transmittance(Ray{Vec3(b, 1.0f, 1.1f), Vec3(-1, 0, 0)}, b - a, rng);
                              }),
                  expected, "step backwards");
    d.file = tile_file;
    const auto tile = load_grid_medium(d);
    const float length = 2;
    expect_within(mean_and_se(20000,
                              [&](int) {
                                return tile->transmittance(Ray{Vec3(1, 1, 1), Vec3(1, 0.5f, 0.25f)}, length, rng);
                              }),
                  beer(sigma_t, 0.5f * length), "tile");
  }
}

// The numbers a tracking call drew from its stream: how many steps of SplitMix64 lie between `before` and `after`,
// found by stepping a copy of `before` until its next three numbers are those of `after`; -1 past `limit`.
long draws_between(MediumRng before, const MediumRng& after, long limit) {
  const auto next_three = [](MediumRng rng) {
    const float a = rng.next(), b = rng.next();
    return std::array<float, 3>{a, b, rng.next()};
  };
  const std::array<float, 3> target = next_three(after);
  for (long n = 0; n <= limit; ++n, before.next())
    if (next_three(before) == target) return n;
  return -1;
}

// The most numbers one tracking call may draw: one a tentative collision up to kMaxTentativeCollisions and one past
// it, and one more each for ratio tracking's roulette or delta tracking's choice of event.
constexpr long kMaxDraws = 2L * kMaxTentativeCollisions + 2;

// Runs `track(rng)` and expects it to draw at most kMaxDraws numbers from `rng`; returns how many it drew (-1: more).
template <typename F>
long expect_bounded_draws(MediumRng& rng, const std::string& what, F track) {
  const MediumRng before = rng;
  track(rng);
  const long n = draws_between(before, rng, kMaxDraws);
  EXPECT_NE(n, -1) << what << " drew more than " << kMaxDraws << " numbers";
  return n;
}

// Tracking a grid far denser than its surroundings: near the densest a medium may be (an optical depth of 9 million
// at its majorant across the grid, kMaxMajorantOpticalDepth 16.8 million), entered through the one-voxel ramp from the
// background. Ratio tracking's estimate is 0, as is the transmittance, exp(-5 x 10^6); every free flight of a medium
// that only scatters scatters, and of one that only absorbs is absorbed (weight 0); and no call draws more numbers
// than its cap of tentative collisions allows. (Delta tracking of the absorbing medium reaches the cap: its weight
// falls through the ramp, 2 x 10^5 tentative collisions, with no roulette to end it, and ends at 0 all the same.)
TEST(MediumGrid, TrackingAVeryDenseGridGivesTheOpaqueLimit) {
  const GridFolder folder;
  const fs::path file = folder.write("constant.vdb", {make_grid(21, [](int, int, int) { return 1.0f; })});
  for (const bool scattering : {true, false}) {
    SCOPED_TRACE(scattering ? "scattering" : "absorbing");
    GridMediumDesc d = desc_of(file, scattering ? Rgb(0) : Rgb(1), scattering ? Rgb(1) : Rgb(0));
    d.density_scale = 4e6f;  // over the bounds' diagonal of 1.3 sqrt(3) units, an optical depth of 9 million
    const auto medium = load_grid_medium(d);
    const Ray ray{Vec3(-0.5f, 0.5f, 0.5f), Vec3(1, 0, 0)};  // 1.3 units through the bounds
    MediumRng rng(13);
    long most = 0;
    for (int i = 0; i < 64; ++i) {
      Rgb tr;
      most = std::max(most, expect_bounded_draws(rng, "ratio tracking",
                                                 [&](MediumRng& r) { tr = medium->transmittance(ray, 2, r); }));
      EXPECT_EQ(tr, Rgb(0));
      FreeFlight f;
      most = std::max(most, expect_bounded_draws(rng, "delta tracking", [&](MediumRng& r) {
                        f = medium->sample_free_flight(ray, 2, Rgb(1), MediumRng(i).next(), r);
                      }));
      if (scattering) {
        EXPECT_TRUE(f.scattered);
        EXPECT_GT(f.t, 0.34f);  // in the ramp from the background, x from -0.15 to -0.1
        EXPECT_LT(f.t, 0.4f);
      } else {
        EXPECT_FALSE(f.scattered);
        EXPECT_EQ(f.weight, Rgb(0));
      }
    }
    std::printf("%s: at most %ld numbers drawn by a call\n", scattering ? "scattering" : "absorbing", most);
  }
}

// Where the majorant is far looser than the extinction, a tracking call ray-marches the rest of its stretch after
// kMaxTentativeCollisions: along a row of a grid of density 2e-7 (at density_scale 5 x 10^6, extinction 1 per unit,
// half of it scattering) whose one dense voxel sets the global majorant (5 x 10^6 per unit, some 6.5 x 10^6
// tentative collisions to cross the row), each call draws at most the numbers its cap allows; ratio tracking's
// estimate is the transmittance exp(-1.25) (the row's optical depth: 1.2 units of voxel centres and the half-voxel
// ramp from the background at each end) within the marching's error, call by call (the tracked part, 0.013 units,
// hardly varies); and free flights cross with expected weight exp(-1.25) and scatter, inside the row, with expected
// weight 0.5 (1 - exp(-1.25)), within their standard errors.
TEST(MediumGrid, TrackingPastTheCapRayMarchesTheRest) {
  const GridFolder folder;
  const fs::path file = folder.write(
      "speck.vdb", {make_grid(21, [](int i, int j, int k) { return i == 18 && j == 18 && k == 18 ? 1.0f : 2e-7f; })});
  GridMediumDesc d = desc_of(file, Rgb(0.5f), Rgb(0.5f));
  d.density_scale = 5e6f;
  d.majorant_grid = false;
  const auto medium = load_grid_medium(d);
  const Ray row{Vec3(-0.5f, 0.1f, 0.1f), Vec3(1, 0, 0)};  // 1.3 units through the bounds, 0.8 from the speck
  const float expected = std::exp(-1.25f);
  MediumRng rng(17);
  Rgb tr;
  for (int i = 0; i < 8; ++i) {
    expect_bounded_draws(rng, "ratio tracking", [&](MediumRng& r) { tr = medium->transmittance(row, 2, r); });
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(tr[c], expected, 0.01f * expected) << "ratio tracking, channel " << c;
  }
  std::vector<FreeFlight> flights(400);
  for (size_t i = 0; i < flights.size(); ++i)
    expect_bounded_draws(rng, "delta tracking", [&](MediumRng& r) {
      flights[i] = medium->sample_free_flight(row, 2, Rgb(1), MediumRng(i).next(), r);
    });
  for (const FreeFlight& f : flights) {
    EXPECT_TRUE(f.scattered || f.t == 2.0f);
    if (f.scattered) {
      EXPECT_TRUE(f.t > 0.35f && f.t < 1.65f) << f.t;
    }
  }
  const auto part = [&](bool scattered) {
    return mean_and_se(static_cast<int>(flights.size()),
                       [&](int i) { return flights[i].scattered == scattered ? flights[i].weight : Rgb(0); });
  };
  const auto crossed = part(false), scattered = part(true);
  std::printf(
      "transmittance (the last) %.4f (expected %.4f); free flights crossing %.4f, scattering %.4f (expected %.4f)\n",
      tr.x, expected, crossed.first.x, scattered.first.x, 0.5f * (1 - expected));
  expect_within(crossed, Rgb(expected), "crossing");
  expect_within(scattered, Rgb(0.5f * (1 - expected)), "scattering");
}

// A closed box mesh over [lo, hi]^3, its triangles' front faces outwards.
json box_object(float lo, float hi, const json& medium) {
  json positions = json::array();
  for (int v = 0; v < 8; ++v)
    for (int a = 0; a < 3; ++a) positions.push_back((v >> a) & 1 ? hi : lo);
  const json indices = {0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5, 0, 1, 5, 0, 5, 4,
                        2, 6, 7, 2, 7, 3, 0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6};
  return {
      {"shape", "mesh"}, {"positions", positions}, {"indices", indices}, {"material", "boundary"}, {"medium", medium}};
}

// The box [0, 1]^3 of medium behind an interface, lit by a lamp and a dim sky, over a floor.
json box_scene(const json& medium) {
  return {
      {"materials",
       {{"boundary", {{"type", "interface"}}},
        {"floor", {{"type", "lambert"}, {"albedo", 0.5}}},
        {"lamp", {{"type", "emission"}, {"radiance", 6}}}}},
      {"objects",
       json::array({box_object(0, 1, medium),
                    {{"shape", "rectangle"},
                     {"corner", {-2, -0.01, 3}},
                     {"edge1", {5, 0, 0}},
                     {"edge2", {0, 0, -5}},
                     {"material", "floor"}},
                    {{"shape", "sphere"}, {"center", {0.5, 2.5, 1.5}}, {"radius", 0.5}, {"material", "lamp"}}})},
      {"camera", {{"from", {1.6, 1.3, 2.6}}, {"to", {0.5, 0.45, 0.5}}, {"fov_deg", 45}}},
      {"environment", {{"color", 0.2}}},
  };
}

RenderSettings render_settings(int size, uint32_t spp, uint64_t seed, const std::string& integrator = "path") {
  RenderSettings s;
  s.integrator.name = integrator;
  s.width = s.height = size;
  s.spp = spp;
  s.seed = seed;
  s.tile_size = 16;
  s.integrator.max_depth = 16;
  return s;
}

std::vector<float> render(const json& doc, const RenderSettings& settings, const fs::path& root) {
  SceneLoadOptions options;
  options.asset_root = root;
  auto scene = load_scene(doc, "/scene", options);
  ThreadPool pool(0);
  RenderSession session(scene, settings, pool);
  session.run();
  return session.film().resolve();
}

// A box of a constant grid renders as the homogeneous medium of the same coefficients in the same box, region by
// region and channel by channel within their standard errors (independent renders); the comparison sees a 5 %
// difference, and the medium is there (the box is darker than without it).
TEST(MediumGrid, AConstantGridRendersAsTheHomogeneousMedium) {
  const GridFolder folder;
  folder.write("constant.vdb", {make_grid(21, [](int, int, int) { return 0.5f; })});
  const json coefficients = {{"sigma_a", {0.4, 0.2, 1.2}}, {"sigma_s", {2.4, 1.0, 3.0}}, {"g", 0.3}};
  json homogeneous = coefficients, grid = coefficients;
  homogeneous["sigma_a"] = {0.2, 0.1, 0.6};  // the grid's density 0.5 times its coefficients
  homogeneous["sigma_s"] = {1.2, 0.5, 1.5};
  grid["grid"] = "constant.vdb";
  const int size = 32, regions = 4, runs = 16;
  const uint32_t spp = 16;
  const auto stats = [&](const json& medium, uint64_t seed, const std::string& integrator) {
    return test::grid_region_stats(runs, size, regions, [&](int k) {
      return render(box_scene(medium), render_settings(size, spp, seed + 7919 * k, integrator), folder.path);
    });
  };
  // 16 regions x 3 channels = 48 comparisons with 15 degrees of freedom each: Bonferroni at a 0.1 % family-wise
  // false alarm rate asks for two-sided p < 2e-5 each, |t_15| < 6.2. The path tracer, and BDPT, whose subpaths from
  // both ends delta-track the grid and whose joins ratio-track it.
  const double bound = 6.2;
  for (const std::string integrator : {"path", "bdpt"}) {
    const test::RegionStats a = stats(homogeneous, 100, integrator), b = stats(grid, 200000, integrator);
    const double z = test::worst_z(a, b);
    std::printf("%s: worst |z| homogeneous vs grid: %.2f\n", integrator.c_str(), z);
    EXPECT_LT(z, bound) << integrator;
    EXPECT_GT(test::worst_z(a, b, 1.05), bound) << integrator;
    const test::RegionStats empty = stats({{"sigma_a", 0}}, 400000, integrator);
    EXPECT_GT(test::worst_z(a, empty), bound) << integrator;
  }
}

// Loading `doc` with assets in `root` (and at most `max_voxels` voxels a grid) fails at `pointer` with `words`.
void expect_error(const json& doc, const fs::path& root, const std::string& pointer, const std::string& words,
                  uint64_t max_voxels = 64'000'000) {
  SceneLoadOptions options;
  options.asset_root = root;
  options.max_grid_voxels = max_voxels;
  try {
    load_scene(doc, "/scene", options);
    ADD_FAILURE() << "no error for " << pointer;
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), pointer) << e.what();
    EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
  }
}

TEST(MediumGrid, BadGridsAreRefusedNamingTheField) {
  const GridFolder folder;
  folder.write("constant.vdb", {make_grid(5, [](int, int, int) { return 1.0f; })});
  folder.write("negative.vdb", {make_grid(5, [](int i, int, int) { return i == 2 ? -0.5f : 1.0f; })});
  folder.write("smoke.vdb", {make_grid(
                                5, [](int, int, int) { return 1.0f; }, "smoke")});
  auto vectors = openvdb::Vec3SGrid::create();
  vectors->setName("density");
  folder.write("vectors.vdb", {vectors});
  std::ofstream(folder.path / "corrupt.vdb") << "this is not an OpenVDB file";
  {
    // A real file cut short.
    std::ifstream in(folder.path / "constant.vdb", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(folder.path / "truncated.vdb", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  }
  const std::string m = "/scene/objects/0/medium";
  const auto doc = [](const json& medium) { return box_scene(medium); };
  SceneLoadOptions options;
  options.asset_root = folder.path;
  EXPECT_NO_THROW(load_scene(doc({{"grid", "constant.vdb"}, {"sigma_s", 1}}), "/scene", options));
  // The file's only float grid is taken when it has none named "density".
  EXPECT_NO_THROW(load_scene(doc({{"grid", "smoke.vdb"}, {"sigma_s", 1}}), "/scene", options));
  expect_error(doc({{"grid", "corrupt.vdb"}}), folder.path, m + "/grid", "not a readable OpenVDB file");
  expect_error(doc({{"grid", "truncated.vdb"}}), folder.path, m + "/grid", "");
  expect_error(doc({{"grid", "missing.vdb"}}), folder.path, m + "/grid", "no such file");
  expect_error(doc({{"grid", "constant.vdb"}}), folder.path, m + "/grid", "more than the 100", 100);
  expect_error(doc({{"grid", "constant.vdb"}, {"grid_name", "smoke"}}), folder.path, m + "/grid_name",
               "no grid \"smoke\" (it has \"density\")");
  expect_error(doc({{"grid", "vectors.vdb"}}), folder.path, m + "/grid", "not float densities");
  expect_error(doc({{"grid", "negative.vdb"}}), folder.path, m + "/grid", "negative densities");
  expect_error(doc({{"grid", "constant.vdb"}, {"sigma_a", -1}}), folder.path, m + "/sigma_a", "");
  expect_error(doc({{"grid", "constant.vdb"}, {"sigma_s", {1, -1, 1}}}), folder.path, m + "/sigma_s/1", "");
  expect_error(doc({{"grid", "constant.vdb"}, {"density_scale", -2}}), folder.path, m + "/density_scale", "");
  expect_error(doc({{"grid", "constant.vdb"}, {"scale", 0}}), folder.path, m + "/scale", "");
  // Past an optical depth of 2^24 = 1.68 x 10^7 at the majorant across the grid's diagonal (0.5 sqrt(3) units here,
  // the voxels' box widened by the one voxel interpolation reaches): 1.65 x 10^7 at 1.9 x 10^7 per unit, 1.73 x 10^7
  // at 2 x 10^7.
  EXPECT_NO_THROW(
      load_scene(doc({{"grid", "constant.vdb"}, {"sigma_s", 1}, {"density_scale", 1.9e7}}), "/scene", options));
  expect_error(doc({{"grid", "constant.vdb"}, {"sigma_s", 1}, {"density_scale", 2e7}}), folder.path,
               m + "/density_scale", "an optical depth of 1.73e+07 across its 0.866 units, more than the 1.68e+07");
  expect_error(doc({{"grid", "constant.vdb"}, {"grid_nam", "x"}}), folder.path, m + "/grid_nam", "grid_name");
  expect_error(doc({{"sigma_a", 1}, {"density_scale", 2}}), folder.path, m + "/density_scale", "with \"grid\"");
  json around = doc({{"sigma_a", 0.1}});
  around["medium"] = {{"grid", "constant.vdb"}};
  expect_error(around, folder.path, "/scene/medium/grid", "needs a boundary");
}

}  // namespace
}  // namespace tessera
