// Textures: image files through OpenImageIO with bilinear filtering and wrap modes, the cache, checkerboards, and
// the asset-folder confinement of texture paths.
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <thread>

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include "renderer/material/material.h"
#include "renderer/scene.h"
#include "renderer/scene_error.h"
#include "renderer/scene_loader.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class TextureTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("tessera-tex-" + std::to_string(::getpid()));
    fs::remove_all(root_);
    fs::create_directories(root_ / "assets" / "sub");
    // A 2 x 1 float image: left texel 0, right texel 1 (EXR: linear, exact).
    write(root_ / "assets" / "ramp.exr", 2, 1, {0.0f, 0.0f, 0.0f, 1.0f, 1.0f, 1.0f});
    write(root_ / "assets" / "sub" / "grey.exr", 1, 1, {0.25f, 0.5f, 0.75f});
    write(root_ / "outside.exr", 1, 1, {1, 1, 1});
    fs::create_symlink(root_ / "outside.exr", root_ / "assets" / "link.exr");
    ctx_.asset_root = root_ / "assets";
  }
  void TearDown() override { fs::remove_all(root_); }

  static void write(const fs::path& file, int w, int h, const std::vector<float>& rgb) {
    auto out = OIIO::ImageOutput::create(file.string());
    ASSERT_TRUE(out);
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::FLOAT);
    ASSERT_TRUE(out->open(file.string(), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, rgb.data()));
    out->close();
  }

  Rgb eval(const json& param, float u, float v) {
    json m = {{"type", "lambert"}, {"albedo", param}};
    auto mat = MaterialRegistry::builtin().create(m, "/m", ctx_);
    ScratchArena arena;
    ShadingPoint sp;
    sp.uv = sp.uv1 = Vec2(u, v);
    return mat->bsdf(sp, arena)->albedo_hint();
  }

  fs::path root_;
  MaterialContext ctx_;
};

TEST_F(TextureTest, BilinearFilteringAndWrapModes) {
  // Texel centres at u = 0.25 (value 0) and 0.75 (value 1); halfway between them 0.5.
  EXPECT_NEAR(eval({{"texture", "ramp.exr"}}, 0.25f, 0.5f).x, 0.0f, 1e-5f);
  EXPECT_NEAR(eval({{"texture", "ramp.exr"}}, 0.75f, 0.5f).x, 1.0f, 1e-5f);
  EXPECT_NEAR(eval({{"texture", "ramp.exr"}}, 0.5f, 0.5f).x, 0.5f, 1e-5f);
  // At u = 0 repeat blends the last texel with the first; clamp holds the first; mirror reflects it.
  EXPECT_NEAR(eval({{"texture", "ramp.exr"}, {"wrap", "repeat"}}, 0.0f, 0.5f).x, 0.5f, 1e-5f);
  EXPECT_NEAR(eval({{"texture", "ramp.exr"}, {"wrap", "clamp"}}, 0.0f, 0.5f).x, 0.0f, 1e-5f);
  EXPECT_NEAR(eval({{"texture", "ramp.exr"}, {"wrap", "mirror"}}, 0.0f, 0.5f).x, 0.0f, 1e-5f);
  EXPECT_NEAR(eval({{"texture", "ramp.exr"}, {"wrap", "repeat"}}, 1.25f, 0.5f).x, 0.0f, 1e-5f);
  EXPECT_NEAR(eval({{"texture", "ramp.exr"}, {"wrap", "clamp"}}, 3.0f, 0.5f).x, 1.0f, 1e-5f);
  EXPECT_NEAR(eval({{"texture", "ramp.exr"}, {"wrap", "mirror"}}, 1.25f, 0.5f).x, 1.0f, 1e-5f);
  // uv scale and the factor.
  EXPECT_NEAR(eval({{"texture", "ramp.exr"}, {"scale", {0.5, 1}}}, 1.5f, 0.5f).x, 1.0f, 1e-5f);
  Rgb c = eval({{"texture", "sub/grey.exr"}, {"factor", 0.5}}, 0.3f, 0.3f);
  EXPECT_NEAR(c.x, 0.125f, 1e-5f);
  EXPECT_NEAR(c.z, 0.375f, 1e-5f);
}

TEST_F(TextureTest, OneFileLoadsOnce) {
  size_t before = texture_cache_loads();
  json m = {{"type", "lambert"}, {"albedo", {{"texture", "sub/grey.exr"}}}};
  auto a = MaterialRegistry::builtin().create(m, "/m", ctx_);
  auto b = MaterialRegistry::builtin().create(m, "/m", ctx_);
  auto c = MaterialRegistry::builtin().create({{"type", "gltf_pbr"}, {"base_color", {{"texture", "sub/grey.exr"}}}},
                                              "/m", ctx_);
  EXPECT_EQ(texture_cache_loads(), before + 1);
}

// Jobs loading the same file at the same moment share one read (the later ones wait for the first); a file that
// cannot be read fails every one of them, and is not remembered as read.
TEST_F(TextureTest, ConcurrentLoadsOfOneFileReadItOnce) {
  std::vector<float> big(512 * 512 * 3);
  for (size_t i = 0; i < big.size(); ++i) big[i] = static_cast<float>(i % 7) / 7;
  write(root_ / "assets" / "big.exr", 512, 512, big);
  std::ofstream(root_ / "assets" / "broken.exr") << "not an image";
  for (const char* file : {"big.exr", "broken.exr"}) {
    SCOPED_TRACE(file);
    const size_t before = texture_cache_loads();
    const json m = {{"type", "lambert"}, {"albedo", {{"texture", file}}}};
    std::vector<std::unique_ptr<Material>> made(8);
    std::atomic<int> ready{0}, failed{0};
    std::vector<std::thread> threads;
    for (size_t t = 0; t < made.size(); ++t)
      threads.emplace_back([&, t] {
        ++ready;
        while (ready.load() < static_cast<int>(made.size())) std::this_thread::yield();  // start together
        try {
          made[t] = MaterialRegistry::builtin().create(m, "/m", ctx_);
        } catch (const SceneError&) {
          ++failed;
        }
      });
    for (std::thread& t : threads) t.join();
    if (std::string(file) == "big.exr") {
      EXPECT_EQ(texture_cache_loads(), before + 1);
      EXPECT_EQ(failed.load(), 0);
      EXPECT_NEAR(eval({{"texture", file}}, 0.5f / 512, 0.5f / 512).y, big[1], 1e-6f);
    } else {
      EXPECT_EQ(texture_cache_loads(), before);
      EXPECT_EQ(failed.load(), static_cast<int>(made.size()));
    }
  }
}

TEST_F(TextureTest, CheckerboardAndScalarChannels) {
  json checker = {{"checker", {{"a", 0.9}, {"b", 0.1}, {"scale", 4}}}};
  EXPECT_NEAR(eval(checker, 0.1f, 0.1f).x, 0.9f, 1e-6f);
  EXPECT_NEAR(eval(checker, 0.3f, 0.1f).x, 0.1f, 1e-6f);
  EXPECT_NEAR(eval(checker, 0.3f, 0.3f).x, 0.9f, 1e-6f);
  // A scalar parameter reads one channel: roughness from G of the grey image (0.5).
  json m = {{"type", "conductor"}, {"roughness", {{"texture", "sub/grey.exr"}, {"channel", 1}}}};
  EXPECT_NO_THROW(MaterialRegistry::builtin().create(m, "/m", ctx_));
  // Checker values are range-checked like constants.
  try {
    MaterialRegistry::builtin().create({{"type", "lambert"}, {"albedo", {{"checker", {{"a", 2}}}}}}, "/m", ctx_);
    ADD_FAILURE();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), "/m/albedo/checker/a");
  }
}

// Hits skip the texture footprint on materials without textures: the registry must tell them apart, whichever
// parameter holds the texture (a model's own, the common emission and normal map, or a nested material's).
TEST_F(TextureTest, MaterialsKnowWhetherTheyReadTextures) {
  const MaterialRegistry& registry = MaterialRegistry::builtin();
  EXPECT_FALSE(registry.create({{"type", "lambert"}, {"albedo", {0.5, 0.4, 0.3}}}, "/m", ctx_)->reads_textures());
  EXPECT_FALSE(registry.create({{"type", "conductor"}, {"roughness", 0.2}}, "/m", ctx_)->reads_textures());
  EXPECT_FALSE(registry.create({{"type", "emission"}, {"radiance", 3}}, "/m", ctx_)->reads_textures());
  const json textured[] = {
      {{"type", "lambert"}, {"albedo", {{"checker", {{"a", 0.9}, {"b", 0.1}}}}}},
      {{"type", "conductor"}, {"roughness", {{"texture", "sub/grey.exr"}, {"channel", 1}}}},
      {{"type", "lambert"}, {"emission", {{"texture", "sub/grey.exr"}}}},
      {{"type", "lambert"}, {"normal_map", {{"texture", "sub/grey.exr"}}}},
      {{"type", "mix"},
       {"a", {{"type", "lambert"}, {"albedo", {{"checker", {{"a", 0.9}}}}}}},
       {"b", {{"type", "lambert"}}}},
  };
  for (const json& m : textured) EXPECT_TRUE(registry.create(m, "/m", ctx_)->reads_textures()) << m.dump();
}

TEST_F(TextureTest, PathsStayInsideTheAssetFolder) {
  auto expect_refused = [&](const std::string& file) {
    try {
      MaterialRegistry::builtin().create({{"type", "lambert"}, {"albedo", {{"texture", file}}}}, "/m", ctx_);
      ADD_FAILURE() << file << " was accepted";
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), "/m/albedo/texture") << file;
    }
  };
  expect_refused((root_ / "outside.exr").string());  // absolute
  expect_refused("../outside.exr");                  // ..
  expect_refused("sub/../../outside.exr");
  expect_refused("link.exr");  // a symlink out of the folder
  expect_refused("missing.png");
  expect_refused("");
  // No asset folder: no file textures at all.
  MaterialContext none;
  EXPECT_THROW(
      MaterialRegistry::builtin().create({{"type", "lambert"}, {"albedo", {{"texture", "ramp.exr"}}}}, "/m", none),
      SceneError);
  // Unknown keys and wrap modes are refused with their pointer.
  try {
    MaterialRegistry::builtin().create({{"type", "lambert"}, {"albedo", {{"texture", "ramp.exr"}, {"wrap", "tile"}}}},
                                       "/m", ctx_);
    ADD_FAILURE();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), "/m/albedo/wrap");
  }
}

// A scene's materials are made side by side (each reads its own image files): each material keeps its own name and
// textures, and of several bad materials the first in the document's order is reported, whatever the timing.
TEST_F(TextureTest, MaterialsMadeSideBySideKeepTheirOrderAndTheFirstError) {
  json materials = json::object();
  for (int i = 0; i < 6; ++i) {
    const float v = 0.1f * (i + 1);
    write(root_ / "assets" / ("t" + std::to_string(i) + ".exr"), 1, 1, {v, v, v});
    materials["m" + std::to_string(i)] = {{"type", "lambert"},
                                          {"albedo", {{"texture", "t" + std::to_string(i) + ".exr"}}}};
  }
  json doc = {{"materials", materials},
              {"objects", {{{"shape", "sphere"}, {"center", {0, 0, 0}}, {"radius", 1}, {"material", "m3"}}}},
              {"camera", {{"from", {0, 0, 5}}, {"to", {0, 0, 0}}}}};
  SceneLoadOptions options;
  options.asset_root = root_ / "assets";
  auto scene = load_scene(doc, "/scene", options);
  ASSERT_EQ(scene->materials.size(), 6u);
  ScratchArena arena;
  ShadingPoint sp;
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(scene->material_names[i], "m" + std::to_string(i));
    EXPECT_NEAR(scene->materials[i]->bsdf(sp, arena)->albedo_hint().x, 0.1f * (i + 1), 1e-6f) << i;
  }
  doc["materials"]["m1"]["albedo"]["texture"] = "missing.exr";
  doc["materials"]["m2"]["type"] = "no-such-model";
  doc["materials"]["m4"]["albedo"]["texture"] = "missing-too.exr";
  for (int run = 0; run < 10; ++run) {
    try {
      load_scene(doc, "/scene", options);
      ADD_FAILURE() << "a scene with bad materials loaded";
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), "/scene/materials/m1/albedo/texture") << e.what();
    }
  }
}

}  // namespace
}  // namespace tessera
