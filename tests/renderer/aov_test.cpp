// Render passes (aov.h): what each pass holds on scenes whose answers are known (the Cornell box's walls, a mirror
// and a pane of glass in front of a wall), the bad requests refused, and the passes' bits independent of threads,
// sample ranges and resumes.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <set>

#include "renderer/aov.h"
#include "renderer/camera.h"
#include "renderer/job.h"
#include "renderer/output.h"
#include "renderer/render_settings.h"
#include "renderer/scene.h"
#include "renderer/scene_error.h"
#include "renderer/session.h"
#include "tests/renderer/pass_test_util.h"

namespace tessera {
namespace {

using nlohmann::json;

const std::vector<std::string> kSurfacePasses = {"albedo",    "normal",    "depth",       "position",    "uv",
                                                 "roughness", "object_id", "material_id", "sample_count"};

using test::cornell_scene;
using test::settings;

// A rendered image's passes by name.
struct Passes {
  int width = 0, height = 0;
  std::map<std::string, std::vector<float>> layers;
  const float* at(const std::string& pass, int x, int y, int channels) const {
    return &layers.at(pass)[(static_cast<size_t>(y) * width + x) * channels];
  }
};

Passes render_passes(const json& scene_doc, const RenderSettings& s, int threads = 2) {
  auto scene = load_scene(scene_doc, "/scene", SceneLoadOptions{});
  ThreadPool pool(threads);
  RenderSession session(scene, s, pool);
  session.run();
  const Image image = resolve_image(session.film(), s.aovs);
  Passes p{image.width, image.height, {}};
  for (const ImageLayer& layer : image.layers) p.layers[layer.name] = layer.pixels;
  return p;
}

// Pixels whose 3 x 3 neighbourhood has one object at sample 0: inside an object's image, away from its edges, where
// every sample of the pixel sees that object too.
std::vector<std::pair<int, int>> interior_pixels(const Passes& p) {
  std::vector<std::pair<int, int>> out;
  for (int y = 1; y + 1 < p.height; ++y)
    for (int x = 1; x + 1 < p.width; ++x) {
      const float id = *p.at("object_id", x, y, 1);
      bool same = id > 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) same = same && *p.at("object_id", x + dx, y + dy, 1) == id;
      if (same) out.emplace_back(x, y);
    }
  return out;
}

// The Cornell box's walls are Lambertian with known albedos; its floor faces up; its objects and materials are
// numbered apart. Path tracing and BDPT record the same passes.
class CornellPasses : public testing::TestWithParam<const char*> {};

TEST_P(CornellPasses, HoldTheWallsAlbedoNormalsIdsAndDepth) {
  const json doc = cornell_scene();
  const RenderSettings s = settings(48, 48, 8, GetParam(), kSurfacePasses);
  const Passes p = render_passes(doc, s);
  const std::vector<std::pair<int, int>> interior = interior_pixels(p);
  ASSERT_GT(interior.size(), 1000u);

  // Albedo: exactly the material's, float for float (every sample adds the same fixed-point value).
  std::map<std::string, Rgb> albedos;
  for (const auto& [name, m] : doc["materials"].items())
    if (m["type"] == "lambert") albedos[name] = Rgb(m["albedo"][0], m["albedo"][1], m["albedo"][2]);
  std::map<float, std::set<float>> materials_of_object;
  std::map<float, std::set<std::vector<float>>> albedos_of_material;
  int floor_pixels = 0, matched = 0;
  for (const auto& [x, y] : interior) {
    const float* a = p.at("albedo", x, y, 3);
    const float object = *p.at("object_id", x, y, 1), material = *p.at("material_id", x, y, 1);
    materials_of_object[object].insert(material);
    albedos_of_material[material].insert({a[0], a[1], a[2]});
    for (const auto& [name, albedo] : albedos)
      if (a[0] == albedo.x && a[1] == albedo.y && a[2] == albedo.z) ++matched;
    EXPECT_EQ(*p.at("sample_count", x, y, 1), 8.0f);
    EXPECT_EQ(*p.at("roughness", x, y, 1), 1.0f);  // Lambertian
    if (object == 1) {                             // the first object: the floor
      ++floor_pixels;
      const float* n = p.at("normal", x, y, 3);
      EXPECT_NEAR(n[0], 0, 1e-6);
      EXPECT_NEAR(n[1], 1, 1e-6);
      EXPECT_NEAR(n[2], 0, 1e-6);
      EXPECT_NEAR(p.at("position", x, y, 3)[1], 0, 1e-6);
    }
  }
  // Every interior pixel but the light's shows a wall's or a box's albedo.
  EXPECT_GT(matched, static_cast<int>(interior.size()) * 9 / 10);
  EXPECT_GT(floor_pixels, 50);
  // Objects (the five walls, the two boxes, and the light where it is large enough to have an interior), each of one
  // material; materials (white, red, green, maybe the light's), each of one albedo.
  EXPECT_GE(materials_of_object.size(), 7u);
  for (const auto& [object, materials] : materials_of_object) EXPECT_EQ(materials.size(), 1u) << object;
  EXPECT_GE(albedos_of_material.size(), 3u);
  for (const auto& [material, set] : albedos_of_material) EXPECT_EQ(set.size(), 1u) << material;

  // Depth: the distance along the camera ray, averaged over the pixel. On the back wall (z = 0.5592) off the image's
  // centre it is longer than the distance along the view axis; the pixel's mean over a fine grid of points in it is
  // what 8 samples estimate, within how much the distance varies over a pixel.
  const Camera camera(load_scene(doc, "/scene", SceneLoadOptions{})->camera, s.width, s.height);
  const int bx = 12, by = 14;  // on the back wall, up and left of the centre
  ASSERT_EQ(*p.at("object_id", bx, by, 1), 3.0f);
  double expected = 0;
  const int grid = 32;
  for (int j = 0; j < grid; ++j)
    for (int i = 0; i < grid; ++i) {
      const Ray r = camera.generate_ray(Vec2(bx + (i + 0.5f) / grid, by + (j + 0.5f) / grid), Vec2(0.5f, 0.5f));
      expected += (0.5592 - r.origin.z) / r.dir.z * length(r.dir);
    }
  expected /= grid * grid;
  EXPECT_NEAR(*p.at("depth", bx, by, 1), expected, 1e-3);
  EXPECT_GT(expected, 0.5592 + 0.8 + 0.01);  // the pixel is far enough from the centre to tell the two apart
}

INSTANTIATE_TEST_SUITE_P(Integrators, CornellPasses, testing::Values("path", "bdpt"));

// A wall of albedo (0.2, 0.5, 0.8) seen through a perfect mirror and through a thin pane of glass: albedo and normal
// are the wall's, times the share of paths that reach it. A mirror of k = 100 reflects all but about 4e-4 of the
// light; the pane reflects R' = 2R / (1 + R) = 0.0769 at normal incidence (R = 0.04 for ior 1.5; pbrt-v4's
// ThinDielectricBxDF), and those paths escape to black: albedo and normal are (1 - R') of the wall's.
json wall_scene(const json& front_material, double wall_z, double front_z) {
  const double s = 4;  // half the rectangles' side: they fill the view
  return json{{"camera", {{"from", {0, 0, -1}}, {"to", {0, 0, 0}}, {"up", {0, 1, 0}}, {"fov_deg", 20}}},
              {"materials",
               {{"wall", {{"type", "lambert"}, {"albedo", {0.2, 0.5, 0.8}}}},
                {"front", front_material},
                {"lamp", {{"type", "emission"}, {"radiance", {1, 1, 1}}}}}},
              {"objects",
               {{{"shape", "rectangle"},
                 {"material", "wall"},
                 {"corner", {-s, -s, wall_z}},
                 {"edge1", {2 * s, 0, 0}},
                 {"edge2", {0, 2 * s, 0}}},
                {{"shape", "rectangle"},
                 {"material", "front"},
                 {"corner", {-s, -s, front_z}},
                 {"edge1", {2 * s, 0, 0}},
                 {"edge2", {0, 2 * s, 0}}},
                {{"shape", "sphere"}, {"material", "lamp"}, {"center", {0, 30, 0}}, {"radius", 1}}}}};
}

// The mean of a pass's channels over the image.
std::vector<double> image_mean(const Passes& p, const std::string& pass, int channels) {
  std::vector<double> mean(static_cast<size_t>(channels), 0.0);
  const std::vector<float>& v = p.layers.at(pass);
  for (size_t i = 0; i < v.size(); ++i) mean[i % static_cast<size_t>(channels)] += v[i];
  for (double& m : mean) m /= static_cast<double>(v.size() / static_cast<size_t>(channels));
  return mean;
}

TEST(AovThroughDelta, AMirrorShowsTheAlbedoAndNormalOfWhatItReflects) {
  // The mirror at z = 0 faces the camera; the wall behind the camera, at z = -3, faces it.
  const json doc = wall_scene({{"type", "conductor"}, {"eta", {0, 0, 0}}, {"k", {100, 100, 100}}}, -3, 0);
  for (const char* integrator : {"path", "bdpt"}) {
    const Passes p = render_passes(doc, settings(16, 16, 4, integrator, {"albedo", "normal", "depth", "object_id"}));
    const std::vector<double> albedo = image_mean(p, "albedo", 3), normal = image_mean(p, "normal", 3);
    EXPECT_NEAR(albedo[0], 0.2, 0.2 * 1e-3) << integrator;
    EXPECT_NEAR(albedo[1], 0.5, 0.5 * 1e-3) << integrator;
    EXPECT_NEAR(albedo[2], 0.8, 0.8 * 1e-3) << integrator;
    EXPECT_NEAR(normal[2], 1, 1e-3) << integrator;  // the wall's normal, facing the mirror (+z)
    // Depth and ids are the mirror's: the first surface the camera ray meets.
    EXPECT_NEAR(*p.at("depth", 8, 8, 1), 1, 1e-3) << integrator;
    EXPECT_EQ(*p.at("object_id", 8, 8, 1), 2.0f) << integrator;
  }
}

TEST(AovThroughDelta, GlassShowsTheAlbedoAndNormalBehindItLessWhatItReflects) {
  const json doc = wall_scene({{"type", "thin_dielectric"}, {"ior", 1.5}}, 1, 0);
  const double r = 0.04, kept = 1 - 2 * r / (1 + r);
  const Passes p = render_passes(doc, settings(32, 32, 64, "path", {"albedo", "normal"}));
  const std::vector<double> albedo = image_mean(p, "albedo", 3), normal = image_mean(p, "normal", 3);
  // 65,536 paths each pass or reflect: the share that passes has a standard error of sqrt(R'(1 - R') / n) = 0.001;
  // off normal incidence (the view is 20 degrees wide) R' grows by under 0.001.
  EXPECT_NEAR(albedo[0] / 0.2, kept, 0.005);
  EXPECT_NEAR(albedo[1] / 0.5, kept, 0.005);
  EXPECT_NEAR(albedo[2] / 0.8, kept, 0.005);
  EXPECT_NEAR(-normal[2], kept, 0.005);  // the wall faces the camera (-z)
}

// Every layer's sums, and the per-pixel counts, of two films.
void expect_same_film(const Film& a, const Film& b) {
  ASSERT_TRUE(a.same_layout(b));
  EXPECT_EQ(a.pixel_sample_counts(), b.pixel_sample_counts());
  for (int i = 0; i < a.layer_count(); ++i) {
    EXPECT_TRUE(a.layer_at(i).sums == b.layer_at(i).sums) << a.layer_at(i).name;
    EXPECT_EQ(a.layer_at(i).hits, b.layer_at(i).hits) << a.layer_at(i).name;
  }
}

TEST(AovBits, EveryPassIsTheSameOnAnyThreadCountSampleSplitAndResume) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  std::vector<std::string> all = kSurfacePasses;
  all.push_back("variance");
  const RenderSettings whole = settings(24, 24, 8, "path", all);
  ThreadPool one(1), many(3);
  RenderSession a(scene, whole, one), b(scene, whole, many);
  a.run();
  b.run();
  expect_same_film(a.film(), b.film());

  // Samples [0, 3) and [3, 8) merged.
  RenderSettings first = whole, second = whole;
  first.spp = 3;
  first.job_spp = 8;
  second.first_sample = 3;
  second.spp = 5;
  second.job_spp = 8;
  RenderSession p1(scene, first, many), p2(scene, second, many);
  p1.run();
  p2.run();
  Film merged = p1.film();
  merged.merge(p2.film());
  expect_same_film(a.film(), merged);

  // Stopped after the first pass, resumed from its film.
  RenderSession resumed(scene, whole, many);
  resumed.restore(p1.film(), 1, 0);
  resumed.run();
  expect_same_film(a.film(), resumed.film());

  // And the image: a job without passes keeps exactly the beauty it had.
  RenderSettings plain = whole;
  plain.aovs.clear();
  RenderSession c(scene, plain, many);
  c.run();
  EXPECT_TRUE(c.film().sums() == a.film().sums());
  EXPECT_EQ(c.film().layer_count(), 1);
}

const std::vector<std::string> kLightPasses = {"emission",          "background",          "volume_direct",
                                               "volume_indirect",   "diffuse_direct",      "diffuse_indirect",
                                               "diffuse_color",     "glossy_direct",       "glossy_indirect",
                                               "glossy_color",      "transmission_direct", "transmission_indirect",
                                               "transmission_color"};

// The largest difference, over pixels and channels, between the beauty and the light passes recomposed as Cycles
// recomposes them, relative to the beauty (plus a floor for black pixels); and each pass's image mean.
double recomposition_error(const Passes& p, std::map<std::string, double>* means) {
  double worst = 0;
  const std::vector<float>& beauty = p.layers.at("");
  for (size_t i = 0; i < beauty.size(); ++i) {
    double sum = 0;
    for (const char* pass : {"emission", "background", "volume_direct", "volume_indirect"}) sum += p.layers.at(pass)[i];
    for (const char* lobe : {"diffuse", "glossy", "transmission"}) {
      const std::string x = lobe;
      sum += (static_cast<double>(p.layers.at(x + "_direct")[i]) + p.layers.at(x + "_indirect")[i]) *
             p.layers.at(x + "_color")[i];
    }
    worst = std::max(worst, std::abs(sum - beauty[i]) / (std::abs(beauty[i]) + 1e-3));
  }
  for (const std::string& pass : kLightPasses) {
    double m = 0;
    for (float v : p.layers.at(pass)) m += v;
    (*means)[pass] = m / static_cast<double>(p.layers.at(pass).size());
  }
  return worst;
}

// The light passes split the beauty without losing or adding anything: recomposed, they are the beauty to float
// rounding on every pixel, and the light goes where it came from; for path tracing and BDPT alike.
class LightPasses : public testing::TestWithParam<const char*> {};

TEST_P(LightPasses, TheCornellBoxRecomposesAndItsLightIsDiffuse) {
  const json doc = cornell_scene();
  const Passes p = render_passes(doc, settings(32, 32, 16, GetParam(), kLightPasses));
  std::map<std::string, double> mean;
  EXPECT_LT(recomposition_error(p, &mean), 1e-5);
  EXPECT_GT(mean["emission"], 0);           // the lamp, seen
  EXPECT_GT(mean["diffuse_direct"], 0.05);  // Lambertian walls lit by the lamp
  EXPECT_GT(mean["diffuse_indirect"], 0.01);
  for (const char* none : {"background", "volume_direct", "volume_indirect", "glossy_direct", "glossy_indirect",
                           "glossy_color", "transmission_direct", "transmission_indirect", "transmission_color"})
    EXPECT_EQ(mean[none], 0) << none;
  // The colour of a wall is its albedo: the interior of the red wall's image.
  const Passes ids = render_passes(doc, settings(32, 32, 16, GetParam(), {"diffuse_color", "material_id"}));
  int red = 0;
  for (int i = 0; i < 32 * 32; ++i)
    if (ids.layers.at("diffuse_color")[3 * i] == 0.63f && ids.layers.at("diffuse_color")[3 * i + 1] == 0.065f) ++red;
  EXPECT_GT(red, 30);
}

TEST_P(LightPasses, GlossGlassAndFogRecomposeAndLandInTheirPasses) {
  // A glossy plastic ball, a glass ball and a ball of fog on a Lambertian floor, under a sky and a lamp (BDPT renders
  // no scattering media: the fog ball is left out for it).
  const bool fog = std::string(GetParam()) == "path";
  json doc = {{"camera", {{"from", {0, 1, -4}}, {"to", {0, 0.5, 0}}, {"up", {0, 1, 0}}, {"fov_deg", 40}}},
              {"environment", {{"color", {0.6, 0.7, 1.0}}}},
              {"materials",
               {{"floor", {{"type", "lambert"}, {"albedo", {0.5, 0.5, 0.5}}}},
                {"plastic", {{"type", "plastic"}, {"diffuse", {0.7, 0.2, 0.1}}, {"roughness", 0.2}}},
                {"glass", {{"type", "dielectric"}, {"ior", 1.5}}},
                {"boundary", {{"type", "interface"}}},
                {"sun", {{"type", "emission"}, {"radiance", {20, 18, 15}}}}}},
              {"objects",
               {{{"shape", "rectangle"},
                 {"material", "floor"},
                 {"corner", {-5, 0, -5}},
                 {"edge1", {0, 0, 10}},
                 {"edge2", {10, 0, 0}}},
                {{"shape", "sphere"}, {"material", "plastic"}, {"center", {-0.7, 0.5, 0}}, {"radius", 0.5}},
                {{"shape", "sphere"}, {"material", "glass"}, {"center", {0.7, 0.5, 0}}, {"radius", 0.5}},
                {{"shape", "sphere"},
                 {"material", "boundary"},
                 {"center", {0, 0.4, -1.2}},
                 {"radius", 0.4},
                 {"medium", {{"sigma_a", {0.1, 0.1, 0.1}}, {"sigma_s", {3, 3, 3}}, {"g", 0}}}},
                {{"shape", "sphere"}, {"material", "sun"}, {"center", {1.6, 1.5, 1.5}}, {"radius", 0.3}}}}};
  if (!fog) doc["objects"].erase(3);
  const Passes p = render_passes(doc, settings(40, 30, 16, GetParam(), kLightPasses));
  std::map<std::string, double> mean;
  EXPECT_LT(recomposition_error(p, &mean), 1e-5);
  for (const char* some : {"emission", "background", "diffuse_direct", "diffuse_indirect", "glossy_direct",
                           "glossy_indirect", "glossy_color", "transmission_indirect", "transmission_color"})
    EXPECT_GT(mean[some], 0) << some;
  for (const char* volume : {"volume_direct", "volume_indirect"}) EXPECT_EQ(mean[volume] > 0, fog) << volume;
}

INSTANTIATE_TEST_SUITE_P(Integrators, LightPasses, testing::Values("path", "bdpt"));

// film_bytes, which the daemon bounds a job's memory by, counts exactly what a film of those passes holds.
TEST(AovSettings, FilmBytesAreWhatTheFilmHolds) {
  for (const std::vector<std::string>& aovs :
       {std::vector<std::string>{}, std::vector<std::string>{"depth"}, std::vector<std::string>{"glossy_color"},
        std::vector<std::string>{"albedo", "sample_count", "variance", "emission"}}) {
    Film film(7, 5);
    add_aov_layers(film, aovs);
    uint64_t held = film.sums_lum2().size() * sizeof(float) + film.pixel_sample_counts().size() * sizeof(uint32_t);
    for (int i = 0; i < film.layer_count(); ++i)
      held += film.layer_at(i).sums.size() * sizeof(FixedSum) + film.layer_at(i).hits.size() * sizeof(uint32_t);
    EXPECT_EQ(film_bytes(7, 5, aovs), held) << aovs.size();
  }
  EXPECT_EQ(film_bytes(1920, 1080, {}), 1920u * 1080u * 56u);
}

TEST(AovSettings, TheContractListsEveryPassOfTheTable) {
  std::ifstream in("proto/schemas/render.schema.json");
  ASSERT_TRUE(in) << "run from the source tree";
  const json aovs = json::parse(in)["properties"]["aovs"];
  std::vector<std::string> names;
  for (const AovInfo& a : aov_table()) names.emplace_back(a.name);
  EXPECT_EQ(aovs["items"]["enum"].get<std::vector<std::string>>(), names);
  EXPECT_EQ(aovs["maxItems"].get<size_t>(), names.size());
}

TEST(AovSettings, NamesAreCheckedAndKeptInOneOrder) {
  const RenderLimits limits;
  const RenderSettings s =
      render_settings_from_json(json{{"aovs", {"depth", "albedo", "sample_count"}}}, "/render", limits);
  EXPECT_EQ(s.aovs, (std::vector<std::string>{"albedo", "depth", "sample_count"}));
  EXPECT_EQ(render_settings_from_text(render_settings_text(s)), s);
  // A job without passes keeps its stored text: no "aovs" key.
  EXPECT_FALSE(render_settings_to_json(RenderSettings{}).contains("aovs"));

  auto refusal = [&](const json& render) -> std::string {
    try {
      render_settings_from_json(render, "/render", limits);
    } catch (const SceneError& e) {
      return e.pointer() + ": " + e.what();
    }
    return "accepted";
  };
  const std::string unknown = refusal(json{{"aovs", {"albedo", "albdo"}}});
  EXPECT_NE(unknown.find("/render/aovs/1"), std::string::npos) << unknown;
  EXPECT_NE(unknown.find("did you mean \"albedo\""), std::string::npos) << unknown;
  EXPECT_NE(refusal(json{{"aovs", {"depth", "depth"}}}).find("twice"), std::string::npos);
  EXPECT_NE(refusal(json{{"aovs", "depth"}}).find("/render/aovs"), std::string::npos);
  const std::string light = refusal(json{{"integrator", "light"}, {"aovs", {"sample_count", "normal"}}});
  EXPECT_NE(light.find("/render/aovs/1"), std::string::npos) << light;
  EXPECT_NE(light.find("light"), std::string::npos) << light;
  EXPECT_NE(refusal(json{{"integrator", "bdpt"}, {"aovs", {"variance"}}}).find("variance"), std::string::npos);
  EXPECT_EQ(refusal(json{{"integrator", "bdpt"}, {"aovs", {"albedo", "depth"}}}), "accepted");
  EXPECT_NE(refusal(json{{"integrator", "light"}, {"aovs", {"sample_count", "glossy_direct"}}}).find("/render/aovs/1"),
            std::string::npos);
  EXPECT_EQ(refusal(json{{"integrator", "bdpt"}, {"aovs", {"glossy_direct"}}}), "accepted");
}

TEST(AovImage, TheExrNamesEveryPassChannelAndKeepsIdsAndDepthInFloat) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  const RenderSettings s = settings(8, 8, 2, "path", {"albedo", "depth", "object_id", "uv", "variance"});
  ThreadPool pool(1);
  RenderSession session(scene, s, pool);
  session.run();
  const Image image = resolve_image(session.film(), s.aovs);
  std::vector<std::string> names;
  for (const ImageLayer& l : image.layers)
    for (const std::string& c : l.channels) names.push_back(l.name.empty() ? c : l.name + "." + c);
  EXPECT_EQ(names, (std::vector<std::string>{"R", "G", "B", "albedo.R", "albedo.G", "albedo.B", "depth.Z", "uv.U",
                                             "uv.V", "object_id.X", "variance.R", "variance.G", "variance.B"}));
  for (const ImageLayer& l : image.layers)
    EXPECT_EQ(l.always_float, l.name == "depth" || l.name == "object_id" || l.name == "variance") << l.name;
}

}  // namespace
}  // namespace tessera
