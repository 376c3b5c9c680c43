// The denoiser (denoise.h) on scenes whose answers are known: a long render as the reference of a textured scene, a
// white furnace, a checkerboard and a hard shadow; its bits on any thread count; the pipeline's layers; bad names.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "renderer/denoise.h"
#include "renderer/output.h"
#include "renderer/render_settings.h"
#include "renderer/scene.h"
#include "renderer/scene_error.h"
#include "renderer/scene_loader.h"
#include "renderer/session.h"

namespace tessera {
namespace {

using nlohmann::json;

// A floor with a checker albedo under a point light (a hard shadow of a box) and a sky; the box and a sphere stand
// on it.
json checker_scene() {
  return json::parse(R"({
    "materials": {
      "floor": {"type": "lambert", "albedo": {"checker": {"a": [0.8, 0.8, 0.8], "b": [0.1, 0.1, 0.1], "scale": 8}}},
      "grey": {"type": "lambert", "albedo": [0.5, 0.5, 0.5]}
    },
    "objects": [
      {"shape": "rectangle", "material": "floor", "corner": [-2, 0, 2], "edge1": [4, 0, 0], "edge2": [0, 0, -4]},
      {"shape": "sphere", "material": "grey", "center": [0.6, 0.4, 0], "radius": 0.4},
      {"shape": "mesh", "material": "grey",
       "positions": [-0.9,0,-0.3, -0.3,0,-0.3, -0.3,0,0.3, -0.9,0,0.3, -0.9,0.6,-0.3, -0.3,0.6,-0.3, -0.3,0.6,0.3, -0.9,0.6,0.3],
       "indices": [0,1,2, 0,2,3, 4,6,5, 4,7,6, 0,4,5, 0,5,1, 1,5,6, 1,6,2, 2,6,7, 2,7,3, 3,7,4, 3,4,0]}
    ],
    "lights": [{"type": "point", "position": [2.5, 2, 0.8], "intensity": [20, 20, 20]}],
    "environment": {"color": [0.25, 0.27, 0.3]},
    "camera": {"from": [0, 2.2, 3.2], "to": [0, 0.2, 0], "fov_deg": 45}
  })");
}

// A low-contrast checkerboard facing the camera, under a sky partly hidden by a sphere: at a few samples the noise
// is about as strong as the texture's contrast.
json checkerboard_scene() {
  return json::parse(R"({
    "materials": {
      "tex": {"type": "lambert", "albedo": {"checker": {"a": [0.6, 0.6, 0.6], "b": [0.4, 0.4, 0.4], "scale": 12}}},
      "grey": {"type": "lambert", "albedo": [0.5, 0.5, 0.5]}
    },
    "objects": [
      {"shape": "rectangle", "material": "tex", "corner": [-1, -1, 0], "edge1": [2, 0, 0], "edge2": [0, 2, 0]},
      {"shape": "sphere", "material": "grey", "center": [0.9, 0.9, 0.7], "radius": 0.6}
    ],
    "environment": {"color": [1, 1, 1]},
    "camera": {"from": [0, 0, 2.6], "to": [0, 0, 0], "fov_deg": 40}
  })");
}

// A diffuse white sphere in a white sky: every pixel is 1 in expectation.
json furnace_scene() {
  return json::parse(R"({
    "materials": {"white": {"type": "lambert", "albedo": [1, 1, 1]}},
    "objects": [{"shape": "sphere", "material": "white", "center": [0, 0, 0], "radius": 1}],
    "environment": {"color": [1, 1, 1]},
    "camera": {"from": [0, 0, 3], "to": [0, 0, 0], "fov_deg": 40}
  })");
}

RenderSettings settings(int size, uint32_t spp, uint64_t seed, Denoiser denoise) {
  RenderSettings s;
  s.width = s.height = size;
  s.spp = spp;
  s.seed = seed;
  s.integrator.max_depth = 6;
  s.tile_size = 16;
  s.denoise = denoise;
  return s;
}

Film render_film(const json& scene_doc, const RenderSettings& s) {
  auto scene = load_scene(scene_doc, "/scene", SceneLoadOptions{});
  ThreadPool pool(2);
  RenderSession session(scene, s, pool);
  session.run();
  return session.take_film();
}

// The image the output pipeline makes of a render (the job's pipeline: its denoiser, its passes).
Image render_image(const json& scene_doc, const RenderSettings& s) {
  return OutputPipeline(s, OutputSpec{}).image(render_film(scene_doc, s));
}

const std::vector<float>& layer(const Image& image, const std::string& name) {
  for (const ImageLayer& l : image.layers)
    if (l.name == name) return l.pixels;
  throw std::runtime_error("no layer " + name);
}

// Relative MSE (Rousselle, Knaus and Zwicker 2011): the mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01).
double relative_mse(const std::vector<float>& x, const std::vector<float>& ref) {
  double sum = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    const double d = x[i] - ref[i];
    sum += d * d / (static_cast<double>(ref[i]) * ref[i] + 0.01);
  }
  return sum / static_cast<double>(x.size());
}

double mean(const std::vector<float>& v) {
  double sum = 0;
  for (float x : v) sum += x;
  return sum / static_cast<double>(v.size());
}

// The luminance's energy of horizontal and vertical differences of neighbours (its high frequencies).
double high_frequency_energy(const std::vector<float>& rgb, int w, int h) {
  auto lum = [&](int x, int y) {
    const size_t i = 3 * (static_cast<size_t>(y) * w + x);
    return 0.2126 * rgb[i] + 0.7152 * rgb[i + 1] + 0.0722 * rgb[i + 2];
  };
  double e = 0;
  for (int y = 0; y + 1 < h; ++y)
    for (int x = 0; x + 1 < w; ++x) {
      const double dx = lum(x + 1, y) - lum(x, y), dy = lum(x, y + 1) - lum(x, y);
      e += dx * dx + dy * dy;
    }
  return e;
}

constexpr int kSize = 64;

class DenoiseTest : public testing::Test {
 protected:
  // One long render, the reference of the checker scene, shared by the tests.
  static void SetUpTestSuite() {
    reference_ = new Image(render_image(checker_scene(), settings(kSize, 2048, 99, Denoiser::kNone)));
  }
  static void TearDownTestSuite() {
    delete reference_;
    reference_ = nullptr;
  }
  static Image* reference_;
};
Image* DenoiseTest::reference_ = nullptr;

TEST_F(DenoiseTest, LowersTheRelativeMseOfATexturedScene) {
  const Image image = render_image(checker_scene(), settings(kSize, 16, 1, Denoiser::kRegression));
  const double noisy = relative_mse(layer(image, "noisy"), reference_->beauty().pixels);
  const double denoised = relative_mse(image.beauty().pixels, reference_->beauty().pixels);
  RecordProperty("noisy_relmse", std::to_string(noisy));
  RecordProperty("denoised_relmse", std::to_string(denoised));
  std::printf("relative MSE at 16 spp: noisy %.5f, denoised %.5f (%.1fx lower)\n", noisy, denoised, noisy / denoised);
  EXPECT_LT(denoised, noisy / 1.4);  // measured 1.8x: the residue is the antialiasing noise of the albedo
}

// The texture is multiplied back after the illumination is filtered: its edges are the reference's, where a filter
// of the beauty would blur them into the noise or keep the noise.
TEST(Denoise, KeepsTheCheckerboardsEdges) {
  const Image reference = render_image(checkerboard_scene(), settings(48, 1024, 99, Denoiser::kNone));
  const Image image = render_image(checkerboard_scene(), settings(48, 8, 2, Denoiser::kRegression));
  const double ref = high_frequency_energy(reference.beauty().pixels, 48, 48);
  const double noisy = high_frequency_energy(layer(image, "noisy"), 48, 48);
  const double denoised = high_frequency_energy(image.beauty().pixels, 48, 48);
  std::printf("high-frequency energy: reference %.4f, noisy %.4f, denoised %.4f\n", ref, noisy, denoised);
  EXPECT_NEAR(denoised / ref, 1.0, 0.1);
}

// The shadow of the box on the floor, beside the light's direct view of the floor: the reference's largest steps
// across the shadow's edge are the denoised image's too.
TEST_F(DenoiseTest, KeepsAHardShadowsEdge) {
  const Image image = render_image(checker_scene(), settings(kSize, 16, 3, Denoiser::kRegression));
  const std::vector<float>& ref = reference_->beauty().pixels;
  // Where the reference's illumination (beauty over albedo) steps by more than 30 % over two pixels: the shadow's
  // edges (the checker's are in the albedo).
  Image features = OutputPipeline(EncodeOptions{}, {}, {"albedo"}).image(render_film(checker_scene(), [] {
    RenderSettings s = settings(kSize, 64, 99, Denoiser::kNone);
    s.aovs = {"albedo"};
    return s;
  }()));
  const std::vector<float>& albedo = layer(features, "albedo");
  auto illum = [&](const std::vector<float>& rgb, size_t i) { return rgb[3 * i + 1] / (albedo[3 * i + 1] + 0.01); };
  double step_ref = 0, step_denoised = 0, step_noisy = 0;
  int edges = 0;
  const std::vector<float>& noisy = layer(image, "noisy");
  for (int y = 0; y + 2 < kSize; ++y)
    for (int x = 0; x + 2 < kSize; ++x)
      for (const size_t step : {size_t{2}, size_t{2 * kSize}}) {  // two pixels right and down: across the edge
        const size_t i = static_cast<size_t>(y) * kSize + x, j = i + step;
        const double a = illum(ref, i), b = illum(ref, j);
        if (std::abs(albedo[3 * i + 1] - albedo[3 * j + 1]) > 1e-3f) continue;  // across a checker edge
        if (std::min(a, b) > 0.7 * std::max(a, b) || std::max(a, b) < 0.3) continue;
        ++edges;
        step_ref += std::abs(a - b);
        step_denoised += std::abs(illum(image.beauty().pixels, i) - illum(image.beauty().pixels, j));
        step_noisy += std::abs(illum(noisy, i) - illum(noisy, j));
      }
  std::printf("shadow edges: %d pixel pairs, mean step: reference %.4f, noisy %.4f, denoised %.4f\n", edges,
              step_ref / edges, step_noisy / edges, step_denoised / edges);
  ASSERT_GT(edges, 10);
  EXPECT_NEAR(step_denoised / step_ref, 1.0, 0.15);
}

TEST(Denoise, AWhiteFurnaceStaysWhite) {
  const Image image = render_image(furnace_scene(), settings(32, 4, 5, Denoiser::kRegression));
  const double noisy = mean(layer(image, "noisy")), denoised = mean(image.beauty().pixels);
  std::printf("white furnace mean: noisy %.6f, denoised %.6f\n", noisy, denoised);
  EXPECT_NEAR(denoised, noisy, 1e-3 * noisy);
  EXPECT_NEAR(denoised, 1.0, 0.01);
  // And whiter: the pixels' RMS deviation from 1 falls.
  auto rms = [](const std::vector<float>& v) {
    double sum = 0;
    for (float x : v) sum += (x - 1.0) * (x - 1.0);
    return std::sqrt(sum / static_cast<double>(v.size()));
  };
  const double rms_noisy = rms(layer(image, "noisy")), rms_denoised = rms(image.beauty().pixels);
  std::printf("white furnace RMS deviation from 1: noisy %.4f, denoised %.4f\n", rms_noisy, rms_denoised);
  EXPECT_LT(rms_denoised, rms_noisy / 3);
}

// Noiseless input (the variance 0) comes out as it went in.
TEST(Denoise, LeavesANoiselessImageAlone) {
  Image image;
  image.width = image.height = 24;
  const size_t n = 24 * 24;
  std::vector<float> beauty(3 * n), albedo(3 * n, 0.5f), normal(3 * n), depth(n, 2.0f), variance(3 * n, 0.0f);
  for (size_t i = 0; i < n; ++i) {
    const float v = static_cast<float>((i * 7919) % 13) / 13.0f;
    for (int c = 0; c < 3; ++c) beauty[3 * i + c] = v * (c + 1);
    normal[3 * i + 2] = 1;
  }
  image.layers = {{"", {"R", "G", "B"}, beauty, false},
                  {"albedo", {"R", "G", "B"}, albedo, false},
                  {"normal", {"X", "Y", "Z"}, normal, false},
                  {"depth", {"Z"}, depth, true},
                  {"variance", {"R", "G", "B"}, variance, true}};
  RegressionDenoiser().apply(image);
  for (size_t i = 0; i < 3 * n; ++i) EXPECT_NEAR(image.beauty().pixels[i], beauty[i], 1e-5f * (1 + beauty[i]));
  EXPECT_EQ(layer(image, "noisy"), beauty);
}

TEST(Denoise, TheSameBitsOnAnyThreadCount) {
  const RenderSettings s = settings(40, 8, 4, Denoiser::kRegression);
  const Film film = render_film(checker_scene(), s);
  RenderSettings features = s;
  features.denoise = Denoiser::kNone;
  features.aovs = film_aovs(s);
  const Image resolved = OutputPipeline(features, OutputSpec{}).image(film);
  std::vector<float> first;
  for (unsigned threads : {1u, 2u, 3u, 8u}) {
    Image image = resolved;
    RegressionDenoiser(RegressionDenoiserOptions{.threads = threads}).apply(image);
    if (first.empty())
      first = image.beauty().pixels;
    else
      EXPECT_EQ(image.beauty().pixels, first) << threads << " threads";
  }
  EXPECT_NE(first, resolved.beauty().pixels);
}

// The job's image holds the passes it asked for and "noisy", not the denoiser's features; the film holds them.
TEST(Denoise, ThePipelineKeepsTheAskedPassesAndTheNoisyImage) {
  RenderSettings s = settings(16, 4, 1, Denoiser::kRegression);
  s.aovs = {"normal"};
  EXPECT_EQ(film_aovs(s), (std::vector<std::string>{"albedo", "normal", "depth", "variance"}));
  const Film film = render_film(checker_scene(), s);
  EXPECT_GE(film.layer("albedo"), 0);
  EXPECT_GE(film.layer("variance"), 0);
  const Image image = OutputPipeline(s, OutputSpec{}).image(film);
  std::vector<std::string> names;
  for (const ImageLayer& l : image.layers) names.push_back(l.name);
  EXPECT_EQ(names, (std::vector<std::string>{"", "noisy", "normal"}));
  EXPECT_EQ(layer(image, "noisy"), film.resolve());
}

TEST(Denoise, SettingsNameTheDenoiserAndRefuseOthers) {
  const json doc = {{"denoise", "regression"}};
  const RenderSettings s = render_settings_from_json(doc, "/render", RenderLimits{});
  EXPECT_EQ(s.denoise, Denoiser::kRegression);
  EXPECT_EQ(render_settings_to_json(s)["denoise"], "regression");
  // The default is left out of the stored text, as records from before it existed have it.
  EXPECT_FALSE(render_settings_to_json(RenderSettings{}).contains("denoise"));
  EXPECT_EQ(render_settings_from_text(render_settings_text(s)), s);
  for (const json& bad : {json("nfor"), json(1), json(nullptr)}) {
    try {
      render_settings_from_json({{"denoise", bad}}, "/render", RenderLimits{});
      ADD_FAILURE() << bad.dump() << " was taken";
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), "/render/denoise");
      EXPECT_NE(std::string(e.what()).find("\"regression\""), std::string::npos) << e.what();
    }
  }
  // The bidirectional integrators cannot make the variance pass it reads.
  try {
    render_settings_from_json({{"denoise", "regression"}, {"integrator", "bdpt"}}, "/render", RenderLimits{});
    ADD_FAILURE() << "bdpt was taken";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), "/render/denoise");
  }
}

}  // namespace
}  // namespace tessera
