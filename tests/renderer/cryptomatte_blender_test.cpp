// A compositor reads tessera's passes: Blender's compositor finds each render pass of the EXR as an output of its
// Image node, and its Cryptomatte node, given the EXR, picks the matte of an object and of a material by name (from
// the manifests in the EXR header), which is, pixel by pixel, the coverage the EXR holds for that name's id. Skipped
// where Blender is not installed (it is not among the test dependencies).
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>

#include "renderer/cryptomatte.h"
#include "renderer/job.h"
#include "renderer/output.h"
#include "renderer/scene.h"
#include "renderer/session.h"
#include "tests/renderer/pass_test_util.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using test::cornell_scene;
using test::settings;

// The coverage of `name`'s id, per pixel, from a Cryptomatte layer of `image`.
std::vector<float> expected_matte(const Image& image, const std::string& pass, const std::string& name) {
  const uint32_t id = cryptomatte::id_of(name);
  for (const ImageLayer& l : image.layers) {
    if (l.name != pass) continue;
    const size_t n = l.channels.size(), pixels = l.pixels.size() / n;
    std::vector<float> matte(pixels, 0.0f);
    for (size_t p = 0; p < pixels; ++p)
      for (size_t r = 0; r + 1 < n; r += 2) {
        uint32_t bits;
        std::memcpy(&bits, &l.pixels[n * p + r], sizeof bits);
        if (bits == id) matte[p] += l.pixels[n * p + r + 1];
      }
    return matte;
  }
  return {};
}

bool have_blender() {
  return std::system("command -v blender >/dev/null 2>&1") == 0;
}

TEST(CryptomatteBlender, BlendersImageNodeFindsEveryPass) {
  if (!have_blender()) GTEST_SKIP() << "Blender is not installed";
  const fs::path dir = fs::temp_directory_path() / ("tessera-blender-passes-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  const std::vector<std::string> passes = {"albedo",    "normal",   "depth",         "uv",
                                           "object_id", "variance", "diffuse_direct"};
  const RenderSettings s = settings(24, 24, 4, "path", passes);
  ThreadPool pool(2);
  RenderSession session(scene, s, pool);
  session.run();
  OutputPipeline(s, OutputSpec{false, true}).run(session.film(), [&](ImageFormat, std::string_view bytes) {
    std::ofstream(dir / "render.exr", std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  });
  const std::string command = "blender -b --factory-startup --python tests/renderer/blender_passes.py -- '" +
                              (dir / "render.exr").string() + "' '" + (dir / "outputs.txt").string() + "' >'" +
                              (dir / "blender.log").string() + "' 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  std::ifstream in(dir / "outputs.txt");
  std::set<std::string> outputs;
  for (std::string line; std::getline(in, line);) outputs.insert(line);
  EXPECT_TRUE(outputs.count("Combined")) << "the beauty";
  for (const std::string& pass : passes) EXPECT_TRUE(outputs.count(pass)) << pass;
  fs::remove_all(dir);
}

TEST(CryptomatteBlender, BlendersCryptomatteNodePicksTheMattesByName) {
  if (!have_blender()) GTEST_SKIP() << "Blender is not installed";
  const fs::path dir = fs::temp_directory_path() / ("tessera-blender-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  nlohmann::json doc = cornell_scene();
  doc["objects"][6]["name"] = "tall box";
  auto scene = load_scene(doc, "/scene", SceneLoadOptions{});
  const RenderSettings s = settings(48, 40, 16, "path", {"crypto_object", "crypto_material"});
  ThreadPool pool(2);
  RenderSession session(scene, s, pool);
  session.run();
  OutputPipeline pipeline(s, OutputSpec{false, true});
  const Image image = pipeline.image(session.film());
  pipeline.publish(image, [&](ImageFormat, std::string_view bytes) {
    std::ofstream(dir / "render.exr", std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  });

  struct Case {
    const char* type;
    const char* pass;
    std::string name;
  };
  for (const Case& c :
       {Case{"CryptoObject", "crypto_object", "tall box"}, Case{"CryptoMaterial", "crypto_material", "red"}}) {
    const fs::path out = dir / (std::string(c.pass) + ".exr");
    const std::string command = "blender -b --factory-startup --python tests/renderer/blender_cryptomatte.py -- '" +
                                (dir / "render.exr").string() + "' " + c.type + " '" + c.name + "' '" + out.string() +
                                "' 48 40 >'" + (dir / "blender.log").string() + "' 2>&1";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    auto in = OIIO::ImageInput::open(out.string());
    ASSERT_TRUE(in) << OIIO::geterror();
    ASSERT_EQ(in->spec().width, 48);
    ASSERT_EQ(in->spec().height, 40);
    std::vector<float> matte(48 * 40);
    ASSERT_TRUE(in->read_image(0, 0, 0, 1, OIIO::TypeDesc::FLOAT, matte.data()));  // R
    const std::vector<float> expected = expected_matte(image, c.pass, c.name);
    ASSERT_EQ(expected.size(), matte.size());
    double covered = 0;
    for (size_t p = 0; p < matte.size(); ++p) {
      EXPECT_NEAR(matte[p], expected[p], 1e-6) << c.name << " at pixel " << p;
      covered += expected[p];
    }
    EXPECT_GT(covered, 20.0) << c.name << " covers some of the image";
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tessera
