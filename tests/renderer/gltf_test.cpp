// glTF import: fixtures written here, rendered, and checked against where things must land and what light must
// arrive; malformed and hostile files must be refused with a SceneError, never a crash.
#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <random>
#include <stop_token>
#include <thread>

#include "renderer/gltf/container.h"
#include "renderer/gltf/loader.h"
#include "renderer/job.h"
#include "renderer/sampling.h"
#include "renderer/scene_error.h"
#include "renderer/scene_loader.h"
#include "renderer/spectrum.h"
#include "tests/renderer/gltf_fixture.h"

namespace tessera {
namespace {

using nlohmann::json;
using test::GltfBuilder;
using test::shared_children_chain;

std::filesystem::path fixture_dir() {
  return test::gltf_fixture_dir();
}

struct Rendered {
  int width, height;
  std::vector<float> rgb;
  Rgb at(int x, int y) const {
    const float* p = &rgb[(static_cast<size_t>(y) * width + x) * 3];
    return {p[0], p[1], p[2]};
  }
};

Rendered render_job(const json& job) {
  JobLoadOptions opts;
  opts.scene.asset_root = fixture_dir();
  RenderJob rj = load_job(job, opts);
  ThreadPool pool(2);
  RenderSession session(rj.scene, rj.settings, pool);
  session.run();
  return {rj.settings.width, rj.settings.height, session.film().resolve()};
}

// A small square in the local xy plane facing +z (counter-clockwise seen from +z), centred at (cx, cy).
void square(GltfBuilder& b, float cx, float cy, float half, int material, int* mesh) {
  *mesh = b.mesh({cx - half, cy - half, 0, cx + half, cy - half, 0, cx + half, cy + half, 0, cx - half, cy + half, 0},
                 {0, 1, 2, 0, 2, 3}, material);
}

TEST(Gltf, NestedTransformsPutAVertexOnItsPixel) {
  for (bool mirrored : {false, true}) {
    GltfBuilder b;
    // One-sided emission: only visible if the winding (and so the normal) survives a mirroring transform.
    int m = b.material({{"emissiveFactor", {1, 1, 1}}, {"doubleSided", false}});
    int mesh;
    square(b, 0.25f, 0.1f, 0.01f, m, &mesh);
    int child = b.node(
        {{"mesh", mesh}, {"translation", {0, 0.5, 0}}, {"rotation", {0, 0, std::sqrt(0.5), std::sqrt(0.5)}}}, false);
    b.node({{"children", {child}}, {"translation", {1, 0, 0}}, {"scale", {mirrored ? -2 : 2, 2, 2}}}, true);
    b.write(fixture_dir(), mirrored ? "nested_mirror" : "nested");
    // Local (0.25, 0.1, 0) -> rotate 90 deg about z: (-0.1, 0.25) -> +(0, 0.5): (-0.1, 0.75) -> scale -> + (1, 0, 0).
    Vec3 expected(1 + (mirrored ? 0.2f : -0.2f), 1.5f, 0);
    json job = {{"kind", "scene"},
                {"scene",
                 {{"gltf", mirrored ? "nested_mirror.gltf" : "nested.gltf"},
                  {"camera", {{"from", {0, 1, 10}}, {"to", {0, 1, 0}}, {"fov_deg", 30}}},
                  {"environment", {{"color", 0}}}}},
                {"render", {{"width", 101}, {"height", 101}, {"spp", 16}, {"max_depth", 1}}}};
    Rendered img = render_job(job);
    int bx = 0, by = 0;
    float best = -1;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x)
        if (img.at(x, y).y > best) {
          best = img.at(x, y).y;
          bx = x;
          by = y;
        }
    CameraDesc cd;
    cd.from = Vec3(0, 1, 10);
    cd.to = Vec3(0, 1, 0);
    cd.fov_deg = 30;
    Vec2 px;
    ASSERT_TRUE(Camera(cd, 101, 101).project(expected, &px));
    EXPECT_GT(best, 0.1f) << (mirrored ? "mirrored: the winding was not flipped" : "nothing visible");
    EXPECT_NEAR(bx + 0.5, px.x, 1.0) << "mirrored=" << mirrored;
    EXPECT_NEAR(by + 0.5, px.y, 1.0) << "mirrored=" << mirrored;
  }
}

// A floor under a light, seen from straight above by a camera with a narrow view: the radiance of a Lambert
// surface of albedo rho is rho / pi times the irradiance.
json lit_floor_job(const std::string& file) {
  return {{"kind", "scene"},
          {"scene",
           {{"gltf", file},
            {"materials", {{"floor", {{"type", "lambert"}, {"albedo", 0.5}}}}},
            {"camera", {{"from", {0, 1, 0}}, {"to", {0, 0, 0}}, {"up", {0, 0, -1}}, {"fov_deg", 2}}},
            {"environment", {{"color", 0}}}}},
          {"render", {{"width", 8}, {"height", 8}, {"spp", 16}, {"max_depth", 1}}}};
}

int floor_mesh(GltfBuilder& b) {
  int m = b.material({{"name", "floor"}});
  return b.mesh({-10, 0, 10, 10, 0, 10, 10, 0, -10, -10, 0, -10}, {0, 1, 2, 0, 2, 3}, m);
}

double mean_green(const Rendered& img) {
  double s = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) s += img.at(x, y).y;
  return s / (img.width * img.height);
}

TEST(Gltf, PointLightGivesTheInverseSquareIrradiance) {
  GltfBuilder b;
  b.node({{"mesh", floor_mesh(b)}}, true);
  const double intensity = 10, d = 2;
  b.doc["extensionsUsed"] = {"KHR_lights_punctual"};
  b.doc["extensions"] = {{"KHR_lights_punctual", {{"lights", {{{"type", "point"}, {"intensity", intensity}}}}}}};
  b.node({{"translation", {0, d, 0}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}, true);
  b.write(fixture_dir(), "point");
  double expected = 0.5 / M_PI * intensity / (d * d);  // rho/pi * I/d^2 (cos = 1 straight below)
  EXPECT_NEAR(mean_green(render_job(lit_floor_job("point.gltf"))), expected, 0.01 * expected);
}

TEST(Gltf, DirectionalLightGivesItsIlluminance) {
  for (double tilt_deg : {0.0, 60.0}) {
    GltfBuilder b;
    b.node({{"mesh", floor_mesh(b)}}, true);
    const double lux = 3;
    b.doc["extensionsUsed"] = {"KHR_lights_punctual"};
    b.doc["extensions"] = {{"KHR_lights_punctual", {{"lights", {{{"type", "directional"}, {"intensity", lux}}}}}}};
    // The light shines down its local -z: rotate -90 deg about x to point it down -y, then tilt about z.
    double a = -M_PI / 4, t = tilt_deg * M_PI / 360;
    json qx = {std::sin(a), 0, 0, std::cos(a)};
    int inner = b.node({{"rotation", qx}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}, false);
    b.node({{"rotation", {0, 0, std::sin(t), std::cos(t)}}, {"children", {inner}}}, true);
    b.write(fixture_dir(), "sun");
    double expected = 0.5 / M_PI * lux * std::cos(tilt_deg * M_PI / 180);
    EXPECT_NEAR(mean_green(render_job(lit_floor_job("sun.gltf"))), expected, 0.01 * expected) << tilt_deg;
  }
}

TEST(Gltf, OrthographicCameraSpansItsMagnification) {
  GltfBuilder b;
  int m = b.material({{"emissiveFactor", {1, 1, 1}}});
  int mesh;
  square(b, 0, 0, 0.5f, m, &mesh);  // 1 x 1 at the origin
  b.node({{"mesh", mesh}}, true);
  b.doc["cameras"] = {
      {{"type", "orthographic"}, {"orthographic", {{"xmag", 1}, {"ymag", 1}, {"znear", 0.1}, {"zfar", 100}}}}};
  b.node({{"camera", 0}, {"translation", {0, 0, 5}}}, true);
  b.write(fixture_dir(), "ortho");
  json job = {{"kind", "scene"},
              {"scene", {{"gltf", "ortho.gltf"}, {"environment", {{"color", 0}}}}},
              {"render", {{"width", 64}, {"height", 64}, {"spp", 4}, {"max_depth", 1}}}};
  Rendered img = render_job(job);
  // The view is 2 units tall (ymag is the half height): the unit square covers a quarter of the image.
  int lit = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) lit += img.at(x, y).y > 0.5f;
  EXPECT_NEAR(lit, 32 * 32, 64);
  EXPECT_GT(img.at(32, 32).y, 0.9f);
  EXPECT_EQ(img.at(2, 2).y, 0.0f);
}

TEST(Gltf, PerspectiveCameraUsesItsVerticalFieldOfView) {
  GltfBuilder b;
  int m = b.material({{"emissiveFactor", {1, 1, 1}}});
  int mesh;
  square(b, 0, 0, 0.5f, m, &mesh);
  b.node({{"mesh", mesh}}, true);
  // yfov chosen so that the unit square at distance d spans half the image height: tan(yfov/2) = 1 / d.
  const double d = 4;
  b.doc["cameras"] = {{{"type", "perspective"},
                       {"perspective", {{"yfov", 2 * std::atan(1 / d)}, {"aspectRatio", 2.0}, {"znear", 0.1}}}}};
  b.node({{"camera", 0}, {"translation", {0, 0, d}}}, true);
  b.write(fixture_dir(), "persp");
  json job = {{"kind", "scene"},
              {"scene", {{"gltf", "persp.gltf"}, {"environment", {{"color", 0}}}}},
              {"render", {{"width", 128}, {"height", 64}, {"spp", 4}, {"max_depth", 1}}}};
  Rendered img = render_job(job);
  int rows = 0, cols = 0;
  for (int y = 0; y < 64; ++y) rows += img.at(64, y).y > 0.5f;
  for (int x = 0; x < 128; ++x) cols += img.at(x, 32).y > 0.5f;
  EXPECT_NEAR(rows, 32, 1);  // half the height
  EXPECT_NEAR(cols, 32, 1);  // square pixels: the same count across
}

TEST(Gltf, EmissiveStrengthScalesEmission) {
  GltfBuilder b;
  b.doc["extensionsUsed"] = {"KHR_materials_emissive_strength"};
  int m = b.material({{"emissiveFactor", {1, 0.5, 0.25}},
                      {"extensions", {{"KHR_materials_emissive_strength", {{"emissiveStrength", 4}}}}}});
  int mesh;
  square(b, 0, 0, 1, m, &mesh);
  b.node({{"mesh", mesh}}, true);
  b.write(fixture_dir(), "strength");
  json job = {{"kind", "scene"},
              {"scene",
               {{"gltf", "strength.gltf"},
                {"camera", {{"from", {0, 0, 3}}, {"to", {0, 0, 0}}, {"fov_deg", 10}}},
                {"environment", {{"color", 0}}}}},
              {"render", {{"width", 8}, {"height", 8}, {"spp", 1}, {"max_depth", 0}}}};
  Rgb c = render_job(job).at(4, 4);
  EXPECT_NEAR(c.x, 4, 1e-4);
  EXPECT_NEAR(c.y, 2, 1e-4);
  EXPECT_NEAR(c.z, 1, 1e-4);
}

TEST(Gltf, GlbAndGltfGiveTheSameScene) {
  GltfBuilder b;
  int m = b.material({{"emissiveFactor", {1, 1, 1}}});
  int mesh;
  square(b, 0, 0, 0.5f, m, &mesh);
  b.node({{"mesh", mesh}}, true);
  GltfBuilder copy = b;
  b.write(fixture_dir(), "same");
  copy.write_glb(fixture_dir(), "same");
  Scene a, c;
  import_gltf(fixture_dir() / "same.gltf", "/scene/gltf", a, {});
  import_gltf(fixture_dir() / "same.glb", "/scene/gltf", c, {});
  ASSERT_EQ(a.meshes.size(), 1u);
  ASSERT_EQ(c.meshes.size(), 1u);
  EXPECT_EQ(a.meshes[0].positions, c.meshes[0].positions);
  EXPECT_EQ(a.meshes[0].indices, c.meshes[0].indices);
}

// ---- hostile and malformed files ----

void expect_refused(const std::filesystem::path& file, const std::string& fragment) {
  Scene scene;
  try {
    import_gltf(file, "/scene/gltf", scene, {});
    ADD_FAILURE() << file << " was accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), "/scene/gltf");
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << "message: " << e.what();
  }
}

GltfBuilder one_triangle() {
  GltfBuilder b;
  int mesh = b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, -1);
  b.node({{"mesh", mesh}}, true);
  return b;
}

std::filesystem::path write_bytes(const std::string& name, const std::vector<unsigned char>& bytes) {
  auto p = fixture_dir() / name;
  std::ofstream(p, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  return p;
}

std::vector<unsigned char> read_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::vector<unsigned char>(std::istreambuf_iterator<char>(in), {});
}

// The loader decodes a buffer's data: URI itself (tinygltf would copy its text three times first), as tinygltf decodes
// it: every variant that tinygltf::DecodeDataURI takes for the buffer loads the same triangle, and every one it
// refuses is refused with tinygltf's message, the URI named by its header.
TEST(GltfHostile, DataUrisAreDecodedAsTinygltfDecodesThem) {
  GltfBuilder triangle = one_triangle();
  triangle.bin.resize(triangle.bin.size() + 2);  // 44 bytes: the base64 ends with a group of three characters
  triangle.write(fixture_dir(), "data-uri");
  const json doc = json::parse(std::ifstream(fixture_dir() / "data-uri.gltf"));
  const std::string header = "data:application/octet-stream;base64,";
  const std::string data = doc["buffers"][0]["uri"].get<std::string>().substr(header.size());
  const std::string bare = data.substr(0, data.find('='));
  ASSERT_NE(bare.size() % 4, 0u) << "the buffer should end with a partial group";
  Scene reference;
  import_gltf(fixture_dir() / "data-uri.gltf", "/scene/gltf", reference, {});
  ASSERT_EQ(reference.meshes.size(), 1u);
  const std::string variants[] = {
      header + data,
      header + bare,                                       // no padding
      header + data + "=AAAA",                             // decoding stops at the first '='
      "data:application/gltf-buffer;base64," + data,       // another header tinygltf reads
      "data:image/png;base64," + data,                     // an image's header, on a buffer
      header + bare.substr(0, bare.size() - 1),            // one character short: a byte short
      header + data.substr(0, 8) + "\n" + data.substr(8),  // decoding stops at a character outside base64
      header,                                              // no bytes
  };
  for (const std::string& uri : variants) {
    SCOPED_TRACE(uri);
    json variant = doc;
    variant["buffers"][0]["uri"] = uri;
    std::ofstream(fixture_dir() / "data-uri-variant.gltf") << variant.dump();
    std::vector<unsigned char> decoded;
    std::string mime;
    if (tinygltf::DecodeDataURI(&decoded, mime, uri, doc["buffers"][0]["byteLength"].get<size_t>(), true)) {
      Scene scene;
      import_gltf(fixture_dir() / "data-uri-variant.gltf", "/scene/gltf", scene, {});
      ASSERT_EQ(scene.meshes.size(), 1u);
      EXPECT_EQ(scene.meshes[0].positions, reference.meshes[0].positions);
      EXPECT_EQ(scene.meshes[0].indices, reference.meshes[0].indices);
    } else {
      expect_refused(fixture_dir() / "data-uri-variant.gltf",
                     "Failed to decode 'uri' : " + uri.substr(0, uri.find(',') + 1) + " in Buffer");
    }
  }
  // An image whose data: URI holds no bytes is refused naming the image, as tinygltf names it.
  GltfBuilder empty_image = one_triangle();
  empty_image.texture_png({});
  empty_image.write(fixture_dir(), "data-uri-empty-image");
  expect_refused(fixture_dir() / "data-uri-empty-image.gltf", "Failed to decode 'uri' for image[0]");
}

TEST(GltfHostile, UrisThatLeaveTheUploadAreRefused) {
  for (const std::string uri : {"../secret.bin", "/etc/passwd", "http://example.com/a.bin", "file:///etc/passwd",
                                "C:\\x.bin", "%2e%2e/x.bin", "sub/../../x.bin", "%2Fetc/passwd",
                                "sub%2F..%2F..%2Fx.bin", ".hidden.bin", "x%zz.bin", "x.bin?y", "sub\\x.bin"}) {
    GltfBuilder b = one_triangle();
    b.write(fixture_dir(), "uri");
    json doc = json::parse(std::ifstream(fixture_dir() / "uri.gltf"));
    doc["buffers"][0]["uri"] = uri;
    std::ofstream(fixture_dir() / "uri.gltf") << doc.dump();
    expect_refused(fixture_dir() / "uri.gltf", "refused URI");
  }
}

// URIs as real assets write them (glTF 2.0, 3.3: reserved characters percent-encoded): "%20" for a space, a leading
// "./", a subfolder; and a symbolic link that leads out of the asset's folder is still refused.
TEST(Gltf, PercentEncodedDotSlashAndSubfolderUrisAreRead) {
  const auto dir = fixture_dir() / "uris";
  std::filesystem::create_directories(dir / "my textures");
  GltfBuilder b = one_triangle();
  b.write(dir, "embedded");  // fills b.bin
  std::ofstream(dir / "my textures" / "tri angle.bin", std::ios::binary)
      .write(reinterpret_cast<const char*>(b.bin.data()), static_cast<std::streamsize>(b.bin.size()));
  std::ofstream(dir / "plain.bin", std::ios::binary)
      .write(reinterpret_cast<const char*>(b.bin.data()), static_cast<std::streamsize>(b.bin.size()));
  for (const std::string uri : {"my%20textures/tri%20angle.bin", "./my%20textures/./tri%20angle.bin", "./plain.bin",
                                "my%20textures/../plain.bin"}) {
    json doc = json::parse(std::ifstream(dir / "embedded.gltf"));
    doc["buffers"][0]["uri"] = uri;
    std::ofstream(dir / "external.gltf") << doc.dump();
    Scene scene;
    if (std::string(uri).find("..") != std::string::npos) {
      expect_refused(dir / "external.gltf", "refused URI");  // ".." is refused even when it stays inside
      continue;
    }
    import_gltf(dir / "external.gltf", "/scene/gltf", scene, {});
    EXPECT_EQ(scene.triangle_count(), 1u) << uri;
    // A .glb naming the same file (its URIs are rewritten for tinygltf inside the container).
    const std::string glb = make_glb(doc.dump(), "");
    std::ofstream(dir / "external.glb", std::ios::binary).write(glb.data(), static_cast<std::streamsize>(glb.size()));
    Scene from_glb;
    import_gltf(dir / "external.glb", "/scene/gltf", from_glb, {});
    EXPECT_EQ(from_glb.triangle_count(), 1u) << uri;
  }
  // A link inside the folder to a file outside it.
  const auto outside = fixture_dir() / "outside.bin";
  std::ofstream(outside, std::ios::binary)
      .write(reinterpret_cast<const char*>(b.bin.data()), static_cast<std::streamsize>(b.bin.size()));
  std::filesystem::remove(dir / "link.bin");
  std::filesystem::create_symlink(outside, dir / "link.bin");
  json doc = json::parse(std::ifstream(dir / "embedded.gltf"));
  doc["buffers"][0]["uri"] = "link.bin";
  std::ofstream(dir / "external.gltf") << doc.dump();
  expect_refused(dir / "external.gltf", "outside the asset");
}

TEST(GltfHostile, MalformedContainersAreRefused) {
  GltfBuilder b = one_triangle();
  auto glb = read_bytes(b.write_glb(fixture_dir(), "good"));
  {
    auto bad = glb;
    bad[0] = 'X';  // wrong magic: then it is not JSON either
    expect_refused(write_bytes("magic.glb", bad), "neither");
  }
  {
    auto bad = glb;
    bad[20] = '!';  // break the JSON chunk
    expect_refused(write_bytes("json.glb", bad), "JSON chunk");
  }
  {
    auto bad = glb;
    bad.resize(bad.size() - 8);  // shorter than the header declares
    expect_refused(write_bytes("short.glb", bad), "declares");
  }
  {
    auto bad = glb;
    bad[4] = 1;  // container version 1
    expect_refused(write_bytes("version.glb", bad), "version");
  }
  {
    auto bad = glb;
    bad.insert(bad.end(), 4, 0);  // longer than the header declares: the container's length is the file's
    expect_refused(write_bytes("padded.glb", bad), "declares");
  }
  expect_refused(write_bytes("empty.glb", {}), "neither");
}

TEST(GltfHostile, InconsistentBuffersAndAccessorsAreRefused) {
  {
    GltfBuilder b = one_triangle();
    b.write(fixture_dir(), "acc");
    json doc = json::parse(std::ifstream(fixture_dir() / "acc.gltf"));
    doc["accessors"][0]["count"] = 1000;  // beyond its buffer view
    std::ofstream(fixture_dir() / "acc.gltf") << doc.dump();
    expect_refused(fixture_dir() / "acc.gltf", "accessor 0");
  }
  {
    GltfBuilder b = one_triangle();
    b.write(fixture_dir(), "huge");
    json doc = json::parse(std::ifstream(fixture_dir() / "huge.gltf"));
    doc["accessors"][0]["count"] = 1099511627776LL;  // 2^40
    std::ofstream(fixture_dir() / "huge.gltf") << doc.dump();
    expect_refused(fixture_dir() / "huge.gltf", "");
  }
  {
    GltfBuilder b = one_triangle();
    b.write(fixture_dir(), "view");
    json doc = json::parse(std::ifstream(fixture_dir() / "view.gltf"));
    doc["bufferViews"][0]["byteLength"] = 4096;  // more than the buffer holds
    std::ofstream(fixture_dir() / "view.gltf") << doc.dump();
    expect_refused(fixture_dir() / "view.gltf", "");
  }
  {
    GltfBuilder b = one_triangle();
    b.write(fixture_dir(), "index");
    json doc = json::parse(std::ifstream(fixture_dir() / "index.gltf"));
    doc["meshes"][0]["primitives"][0]["indices"] = 0;  // positions used as indices: wrong type
    std::ofstream(fixture_dir() / "index.gltf") << doc.dump();
    expect_refused(fixture_dir() / "index.gltf", "");
  }
  {
    GltfBuilder b = one_triangle();
    b.doc["scene"] = 3;  // the default scene, of one
    expect_refused(b.write(fixture_dir(), "scene"), "the asset's scene 3 does not exist (it has 1 scenes)");
  }
  {
    GltfBuilder b = one_triangle();
    b.node({{"children", {0}}}, false);
    b.doc["nodes"][0]["children"] = {1};  // a cycle
    b.write(fixture_dir(), "cycle");
    expect_refused(fixture_dir() / "cycle.gltf", "");
  }
}

// Nodes may share children (against the specification, which wants trees): the paths through the hierarchy are
// counted, not the nodes, and refused above the limit before anything is made, at once.
TEST(GltfHostile, SharedChildrenAreCountedPerPathAndRefusedAboveTheLimit) {
  for (int levels : {30, 11}) {  // 4^30 and 4^11 instances of one triangle, from files of about 1 KB
    const auto file = shared_children_chain(levels, 4, true).write_glb(fixture_dir(), "chain" + std::to_string(levels));
    const auto started = std::chrono::steady_clock::now();
    expect_refused(file, "more than 1000000 node instances, the limit");
    EXPECT_LT(std::chrono::steady_clock::now() - started, std::chrono::seconds(1)) << levels << " levels";
  }
  // Within the limit, shared children are instances: 4^3 triangles from one mesh, 1 + 4 + 16 + 64 nodes.
  const auto small = shared_children_chain(3, 4, true).write_glb(fixture_dir(), "chain3");
  Scene scene;
  GltfImportOptions options;
  options.max_instances = 85;
  import_gltf(small, "/scene/gltf", scene, options);
  EXPECT_EQ(scene.instances.size(), 64u);
  Scene again;
  options.max_instances = 84;
  EXPECT_THROW(import_gltf(small, "/scene/gltf", again, options), SceneError);
}

// A load that takes long (here 4^14 node instances, allowed) ends soon after its stop token is asked to stop: a
// daemon shutting down, a job cancelled or paused.
TEST(GltfHostile, AStopTokenEndsALongLoad) {
  const auto file = shared_children_chain(14, 4, false).write_glb(fixture_dir(), "long");
  std::stop_source stop;
  GltfImportOptions options;
  options.max_instances = uint64_t{1} << 40;
  options.stop = stop.get_token();
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    stop.request_stop();
  });
  const auto started = std::chrono::steady_clock::now();
  Scene scene;
  EXPECT_THROW(import_gltf(file, "/scene/gltf", scene, options), LoadStopped);
  stopper.join();
  EXPECT_LT(std::chrono::steady_clock::now() - started, std::chrono::seconds(5));
  // A scene document's load ends the same way.
  SceneLoadOptions scene_options;
  scene_options.asset_root = fixture_dir();
  scene_options.max_gltf_instances = options.max_instances;
  scene_options.stop = stop.get_token();
  EXPECT_THROW(load_scene(json{{"gltf", "long.glb"}}, "/scene", scene_options), LoadStopped);
}

// An accessor without a buffer view is zeros that the import makes (glTF 2.0, 5.1 accessor.bufferView): a file of a
// few hundred bytes could declare gigabytes of them. Its count is held against the vertex limit, and its bytes
// against what the asset's own bytes allow, before anything is made.
TEST(GltfHostile, AccessorsWithoutDataAreBoundedBeforeTheyAreMade) {
  const std::pair<uint64_t, const char*> cases[] = {{150'000'000, "the limit of 50000000 vertices"},
                                                    {30'000'000, "MiB, the limit for an asset of this size"}};
  for (const auto& [count, refusal] : cases) {
    GltfBuilder b = one_triangle();
    b.write(fixture_dir(), "zeros");
    json doc = json::parse(std::ifstream(fixture_dir() / "zeros.gltf"));
    doc["accessors"][0].erase("bufferView");
    doc["accessors"][0]["count"] = count;
    std::ofstream(fixture_dir() / "zeros.gltf") << doc.dump();
    expect_refused(fixture_dir() / "zeros.gltf", refusal);
  }
  // Within both, zeros are read as zeros: a triangle of three vertices at the origin.
  GltfBuilder b = one_triangle();
  b.write(fixture_dir(), "few_zeros");
  json doc = json::parse(std::ifstream(fixture_dir() / "few_zeros.gltf"));
  doc["accessors"][0].erase("bufferView");
  std::ofstream(fixture_dir() / "few_zeros.gltf") << doc.dump();
  Scene scene;
  import_gltf(fixture_dir() / "few_zeros.gltf", "/scene/gltf", scene, {});
  ASSERT_EQ(scene.meshes.size(), 1u);
  for (const Vec3& p : scene.meshes[0].positions) EXPECT_EQ(length(p), 0.0f);
}

// Geometry Embree could not trace (a coordinate beyond kMaxSceneCoordinate, or one that a node's transform takes
// past the largest float) is refused when the scene is loaded, naming it, never handed to the renderer.
TEST(GltfHostile, GeometryBeyondTheSceneExtentIsRefused) {
  {
    GltfBuilder b;
    b.node({{"mesh", b.mesh({0, 0, 0, 3e38f, 0, 0, 0, 1, 0}, {0, 1, 2}, -1)}}, true);
    b.write(fixture_dir(), "far");
    SceneLoadOptions options;
    options.asset_root = fixture_dir();
    try {
      load_scene(json{{"gltf", "far.gltf"}}, "/scene", options);
      ADD_FAILURE() << "a vertex at 3e38 was accepted";
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), "/scene");
      EXPECT_NE(std::string(e.what()).find("reaches 3e+38 units from the origin, beyond the 1e+12"), std::string::npos)
          << e.what();
    }
  }
  {
    GltfBuilder b = one_triangle();
    b.doc["nodes"][0]["scale"] = {1e30, 1e30, 1e30};
    b.node({{"scale", {1e30, 1e30, 1e30}}, {"children", {0}}}, true);
    b.doc["scenes"][0]["nodes"] = {1};
    b.write(fixture_dir(), "overflow");
    SceneLoadOptions options;
    options.asset_root = fixture_dir();
    EXPECT_THROW(load_scene(json{{"gltf", "overflow.gltf"}}, "/scene", options), SceneError);
  }
  // A JSON scene's sphere, whose coordinates the contract allows up to 1e30, is held to the same extent.
  const json far_sphere = {
      {"materials", {{"m", {{"type", "lambert"}}}}},
      {"objects", {{{"shape", "sphere"}, {"center", {1e20, 0, 0}}, {"radius", 1}, {"material", "m"}}}}};
  EXPECT_THROW(load_scene(far_sphere, "/scene", {}), SceneError);
}

// A ray Embree 3 would abort on (a component of its origin or direction beyond 1.844e18, a NaN anywhere) is answered
// as a miss, alone or in a packet, and the rays beside it in the packet are traced as ever.
TEST(GltfHostile, RaysEmbreeCannotTraceAreMisses) {
  Scene scene;
  import_gltf(one_triangle().write(fixture_dir(), "traced"), "/scene/gltf", scene, {});
  scene.finalize();
  const Ray good{Vec3(0.25f, 0.25f, 1), Vec3(0, 0, -1)};
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const Ray bad[] = {{Vec3(nan, 0.25f, 1), Vec3(0, 0, -1)},
                     {Vec3(0.25f, 0.25f, 1), Vec3(0, nan, -1)},
                     {Vec3(0.25f, 0.25f, 3e18f), Vec3(0, 0, -1)},
                     {Vec3(0.25f, 0.25f, 1), Vec3(0, 0, -1), nan},
                     {Vec3(0.25f, 0.25f, 1), Vec3(0, 0, -1), 0, nan}};
  RayHit hit;
  EXPECT_TRUE(scene.accel().intersect(good, &hit));
  for (const Ray& ray : bad) {
    EXPECT_FALSE(scene.accel().intersect(ray, &hit));
    EXPECT_FALSE(scene.accel().occluded(ray));
  }
  Ray packet[Accel::kPacketSize];
  for (int i = 0; i < Accel::kPacketSize; ++i) packet[i] = i % 2 ? bad[i / 2 % 5] : good;
  RayHit hits[Accel::kPacketSize];
  bool found[Accel::kPacketSize];
  scene.accel().intersect_packet(packet, Accel::kPacketSize, hits, found);
  for (int i = 0; i < Accel::kPacketSize; ++i) EXPECT_EQ(found[i], i % 2 == 0) << "ray " << i;
}

// An asset listing ten thousand extensions nobody knows makes one warning that names a few and counts the rest, at
// once; a scene's warnings are at most kMaxWarnings, each once, then a count of the rest.
TEST(GltfHostile, ManyUnknownExtensionsMakeOneWarning) {
  GltfBuilder b = one_triangle();
  b.doc["extensionsUsed"] = json::array();
  for (int i = 0; i < 10000; ++i) b.doc["extensionsUsed"].push_back("EXT_unknown_" + std::to_string(i));
  Scene scene;
  const GltfImport imported = import_gltf(b.write(fixture_dir(), "extensions"), "/scene/gltf", scene, {});
  ASSERT_EQ(imported.warnings.size(), 1u);
  EXPECT_NE(imported.warnings[0].find("EXT_unknown_0, "), std::string::npos) << imported.warnings[0];
  EXPECT_NE(imported.warnings[0].find(" and 9992 more are not supported and were ignored"), std::string::npos)
      << imported.warnings[0];

  std::vector<std::string> warnings;
  for (int i = 0; i < 100; ++i) warnings.push_back("material " + std::to_string(i % 50) + " is approximated");
  tidy_warnings(&warnings);
  ASSERT_EQ(warnings.size(), kMaxWarnings + 1);
  EXPECT_EQ(warnings.front(), "material 0 is approximated");
  EXPECT_EQ(warnings.back(), "and " + std::to_string(50 - kMaxWarnings) + " more warnings");
  // Tidied again with more (a scene holding an asset's tidied warnings), the counts add up.
  warnings.push_back("the scene's own warning");
  warnings.push_back("and 5 more warnings");
  tidy_warnings(&warnings);
  EXPECT_EQ(warnings.back(), "and " + std::to_string(50 - kMaxWarnings + 1 + 5) + " more warnings");
}

// What is not rendered as written says so, once, naming the node or material: a node's own morph weights. A
// clearcoat normal map is applied, and no warning says otherwise.
TEST(Gltf, FeaturesNotAppliedAreWarnings) {
  GltfBuilder b = one_triangle();
  b.doc["meshes"][0]["primitives"][0]["targets"] = {{{"POSITION", 0}}};
  b.doc["meshes"][0]["weights"] = {0};
  b.doc["nodes"][0]["weights"] = {0.5};
  b.node({{"mesh", 0}}, true);  // the same mesh again: its warning comes once
  b.doc["extensionsUsed"] = {"KHR_materials_clearcoat"};
  b.material({{"name", "coat"},
              {"extensions",
               {{"KHR_materials_clearcoat", {{"clearcoatFactor", 1}, {"clearcoatNormalTexture", {{"index", 0}}}}}}}});
  b.doc["meshes"][0]["primitives"][0]["material"] = 0;
  b.write(fixture_dir(), "not_applied");
  Scene scene;
  GltfImport imp = import_gltf(fixture_dir() / "not_applied.gltf", "/scene/gltf", scene, {});
  std::string all;
  for (const std::string& w : imp.warnings) all += w + "\n";
  EXPECT_NE(all.find("node 0: its own morph weights are not applied"), std::string::npos) << all;
  EXPECT_EQ(all.find("clearcoatNormalTexture"), std::string::npos) << all;
}

// Morph targets at the mesh's default weights: a vertex lands at its position plus the weighted displacements.
TEST(Gltf, MorphTargetsAreAppliedAtTheDefaultWeights) {
  GltfBuilder b = one_triangle();
  const int up = b.floats({0, 1, 0, 0, 1, 0, 0, 1, 0}, "VEC3", 3),
            right = b.floats({2, 0, 0, 0, 0, 0, 0, 0, 0}, "VEC3", 3);
  b.doc["meshes"][0]["primitives"][0]["targets"] = {{{"POSITION", up}}, {{"POSITION", right}}};
  b.doc["meshes"][0]["weights"] = {0.5, 0.25};
  b.write(fixture_dir(), "morph");
  Scene scene;
  import_gltf(fixture_dir() / "morph.gltf", "/scene/gltf", scene, {});
  ASSERT_EQ(scene.meshes.size(), 1u);
  const std::vector<Vec3>& p = scene.meshes[0].positions;
  EXPECT_NEAR(p[0].x, 0.5, 1e-6);  // (0, 0, 0) + 0.5 (0, 1, 0) + 0.25 (2, 0, 0)
  EXPECT_NEAR(p[0].y, 0.5, 1e-6);
  EXPECT_NEAR(p[1].x, 1, 1e-6);  // (1, 0, 0) + 0.5 (0, 1, 0)
  EXPECT_NEAR(p[1].y, 0.5, 1e-6);
  EXPECT_NEAR(p[2].y, 1.5, 1e-6);
}

// A skinned mesh is posed by its joints' node transforms times their inverse bind matrices, blended by WEIGHTS_0; the
// skinned node's own transform is not used.
TEST(Gltf, SkinsArePosedByTheirJoints) {
  GltfBuilder b = one_triangle();
  // Vertex 0 follows joint 0 alone, vertex 1 joint 1 alone, vertex 2 half of each.
  const int joints = b.floats({0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0}, "VEC4", 4);
  b.doc["accessors"][joints]["componentType"] = 5126;  // as floats here; the loader reads any component type
  const int weights = b.floats({1, 0, 0, 0, 1, 0, 0, 0, 0.5, 0.5, 0, 0}, "VEC4", 4);
  b.doc["meshes"][0]["primitives"][0]["attributes"]["JOINTS_0"] = joints;
  b.doc["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_0"] = weights;
  // Joint 0 at (0, 0, -5); joint 1 at (10, 0, -5) with an inverse bind matrix that undoes a bind at x = 1.
  const int ibm = b.floats({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0,  0, 0, 1,  //
                            1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1},
                           "MAT4", 16);
  b.doc["nodes"][0]["skin"] = 0;
  b.doc["nodes"][0]["translation"] = {100, 100, 100};  // not used for a skinned mesh
  const int j0 = b.node({{"translation", {0, 0, -5}}}, true), j1 = b.node({{"translation", {10, 0, -5}}}, true);
  b.doc["skins"] = {{{"joints", {j0, j1}}, {"inverseBindMatrices", ibm}}};
  b.write(fixture_dir(), "skin");
  Scene scene;
  import_gltf(fixture_dir() / "skin.gltf", "/scene/gltf", scene, {});
  ASSERT_EQ(scene.meshes.size(), 1u);
  const std::vector<Vec3>& p = scene.meshes[0].positions;
  EXPECT_NEAR(p[0].x, 0, 1e-5);  // (0, 0, 0) by joint 0
  EXPECT_NEAR(p[0].z, -5, 1e-5);
  EXPECT_NEAR(p[1].x, 10, 1e-5);  // (1, 0, 0) by joint 1: -1, then +10
  EXPECT_NEAR(p[1].z, -5, 1e-5);
  EXPECT_NEAR(p[2].x, 4.5, 1e-5);  // (0, 1, 0): half (0, 1, -5), half (9, 1, -5)
  EXPECT_NEAR(p[2].y, 1, 1e-5);
  EXPECT_NEAR(p[2].z, -5, 1e-5);
}

// EXT_mesh_gpu_instancing: one node draws its mesh once per instance, at the node's transform times each instance's
// TRANSLATION * ROTATION * SCALE.
TEST(Gltf, GpuInstancingDrawsEveryInstance) {
  GltfBuilder b;
  b.doc["extensionsUsed"] = {"EXT_mesh_gpu_instancing"};
  b.doc["extensionsRequired"] = {"EXT_mesh_gpu_instancing"};
  int mesh = b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, -1);
  std::vector<float> t, r, sc;
  for (int i = 0; i < 125; ++i) {
    t.insert(t.end(), {2.0f * (i % 5), 2.0f * (i / 5 % 5), 2.0f * (i / 25)});
    const bool turned = i == 7;  // a quarter turn about z, scaled by 2
    r.insert(r.end(), {0, 0, turned ? std::sqrt(0.5f) : 0.0f, turned ? std::sqrt(0.5f) : 1.0f});
    sc.insert(sc.end(), {turned ? 2.0f : 1.0f, turned ? 2.0f : 1.0f, turned ? 2.0f : 1.0f});
  }
  const int ta = b.floats(t, "VEC3", 3), ra = b.floats(r, "VEC4", 4), sa = b.floats(sc, "VEC3", 3);
  b.node({{"mesh", mesh},
          {"translation", {0, 0, -10}},
          {"extensions",
           {{"EXT_mesh_gpu_instancing", {{"attributes", {{"TRANSLATION", ta}, {"ROTATION", ra}, {"SCALE", sa}}}}}}}},
         true);
  b.write(fixture_dir(), "gpu_instancing");
  Scene scene;
  GltfImport imp = import_gltf(fixture_dir() / "gpu_instancing.gltf", "/scene/gltf", scene, {});
  EXPECT_TRUE(imp.warnings.empty()) << imp.warnings[0];
  ASSERT_EQ(scene.instances.size(), 125u);
  EXPECT_EQ(scene.meshes.size(), 1u);  // one object-space copy
  const Vec3 last = scene.instances[124].to_world.point(Vec3(1, 0, 0));
  EXPECT_NEAR(last.x, 9, 1e-5);
  EXPECT_NEAR(last.y, 8, 1e-5);
  EXPECT_NEAR(last.z, -2, 1e-5);
  const Vec3 turned = scene.instances[7].to_world.point(Vec3(1, 0, 0));  // instance 7 at (4, 2, 0)
  EXPECT_NEAR(turned.x, 4, 1e-5);
  EXPECT_NEAR(turned.y, 4, 1e-5);
  EXPECT_NEAR(turned.z, -10, 1e-5);
}

TEST(GltfHostile, RequiredUnsupportedExtensionFailsOptionalWarns) {
  GltfBuilder b = one_triangle();
  b.doc["extensionsUsed"] = {"EXT_unknown_thing"};
  b.doc["extensionsRequired"] = {"EXT_unknown_thing"};
  b.write(fixture_dir(), "required");
  expect_refused(fixture_dir() / "required.gltf", "EXT_unknown_thing");
  b.doc.erase("extensionsRequired");
  b.write(fixture_dir(), "optional");
  Scene scene;
  GltfImport imp = import_gltf(fixture_dir() / "optional.gltf", "/scene/gltf", scene, {});
  ASSERT_EQ(imp.warnings.size(), 1u);
  EXPECT_NE(imp.warnings[0].find("EXT_unknown_thing"), std::string::npos);
}

// glTF's subsurface drafts are not read (their mapping of the multiple-scattering colour is still changing): an asset
// that requires one is refused naming it, rather than rendered without its scattering; one that only uses it warns.
TEST(GltfHostile, SubsurfaceDraftsAreRefusedWhenRequired) {
  for (const char* name : {"KHR_materials_scatter", "KHR_materials_volume_scatter"}) {
    GltfBuilder b = one_triangle();
    b.doc["extensionsUsed"] = {name, "KHR_materials_volume"};
    b.doc["extensionsRequired"] = {name};
    b.write(fixture_dir(), "scatter_required");
    expect_refused(fixture_dir() / "scatter_required.gltf", name);
    b.doc.erase("extensionsRequired");
    b.write(fixture_dir(), "scatter_used");
    Scene scene;
    GltfImport imp = import_gltf(fixture_dir() / "scatter_used.gltf", "/scene/gltf", scene, {});
    ASSERT_EQ(imp.warnings.size(), 1u) << name;
    EXPECT_NE(imp.warnings[0].find(name), std::string::npos) << imp.warnings[0];
  }
}

// The public sample assets of examples/ import without warnings and render something; an animated one (the spinning
// cube) posed at a time, since without one the warning that its animation is not applied is right.
TEST(Gltf, SampleAssetsRenderWithoutWarnings) {
  const std::filesystem::path scenes = "examples";  // tests run in the repository root
  int found = 0;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(scenes)) {
    if (entry.path().extension() != ".glb" && entry.path().extension() != ".gltf") continue;
    ++found;
    JobLoadOptions opts;
    opts.scene.asset_root = entry.path().parent_path();
    json job = {{"kind", "scene"},
                {"scene", {{"gltf", entry.path().filename().string()}}},
                {"render", {{"width", 48}, {"height", 32}, {"spp", 2}}}};
    RenderJob rj = load_job(job, opts);
    if (rj.scene->warnings.size() == 1 && rj.scene->warnings[0].find(" not applied: its nodes are rendered as they are "
                                                                     "stated") != std::string::npos) {
      job["scene"]["time"] = 1;
      rj = load_job(job, opts);
    }
    EXPECT_TRUE(rj.scene->warnings.empty()) << entry.path() << ": " << rj.scene->warnings.front();
    EXPECT_GT(rj.scene->triangle_count(), 0u) << entry.path();
    ThreadPool pool(2);
    RenderSession session(rj.scene, rj.settings, pool);
    session.run();
    std::vector<float> rgb = session.film().resolve();
    double sum = 0;
    for (float v : rgb) sum += v;
    EXPECT_GT(sum, 0) << entry.path();
  }
  EXPECT_GE(found, 3);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// One mesh referenced by three nodes is traced through Embree instances; the image equals that of three copies.
TEST(Gltf, RepeatedMeshesAreInstancedAndRenderLikeCopies) {
  auto build = [](bool shared) {
    GltfBuilder b;
    int m = b.material({{"name", "grey"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.7, 0.7, 0.7, 1}}}}});
    // A unit cube's front and top faces are enough to show orientation and shading.
    std::vector<float> pos = {-0.5f, -0.5f, 0.5f, 0.5f, -0.5f, 0.5f, 0.5f, 0.5f, 0.5f,  -0.5f, 0.5f, 0.5f,
                              -0.5f, 0.5f,  0.5f, 0.5f, 0.5f,  0.5f, 0.5f, 0.5f, -0.5f, -0.5f, 0.5f, -0.5f};
    std::vector<uint16_t> idx = {0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7};
    int first = b.mesh(pos, idx, m);
    json scales = {{1, 1, 1}, {-1, 1, 1}, {1, 2, 1}};
    for (int i = 0; i < 3; ++i) {
      int mesh = shared ? first : (i == 0 ? first : b.mesh(pos, idx, m));
      b.node({{"mesh", mesh}, {"translation", {-2.0 + 2 * i, 0, 0}}, {"scale", scales[i]}}, true);
    }
    return b;
  };
  build(true).write(fixture_dir(), "instanced");
  build(false).write(fixture_dir(), "copies");
  Scene scene;
  import_gltf(fixture_dir() / "instanced.gltf", "/scene/gltf", scene, {});
  EXPECT_EQ(scene.groups.size(), 1u);
  EXPECT_EQ(scene.instances.size(), 3u);
  EXPECT_TRUE(scene.instances[1].mirrored);
  auto job = [](const std::string& file) {
    return json{{"kind", "scene"},
                {"scene",
                 {{"gltf", file},
                  {"camera", {{"from", {0, 2, 6}}, {"to", {0, 0, 0}}, {"fov_deg", 45}}},
                  {"environment", {{"color", 1}}}}},
                {"render", {{"width", 64}, {"height", 32}, {"spp", 16}, {"max_depth", 2}}}};
  };
  Rendered a = render_job(job("instanced.gltf")), c = render_job(job("copies.gltf"));
  double diff = 0, total = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) {
    diff += std::abs(a.rgb[i] - c.rgb[i]);
    total += c.rgb[i];
  }
  // The same sample sequence through the same geometry: identical up to float rounding at silhouettes.
  EXPECT_LT(diff / total, 1e-3);
  JobLoadOptions opts;
  opts.scene.asset_root = fixture_dir();
  RenderJob rj = load_job(job("instanced.gltf"), opts);
  EXPECT_EQ(rj.scene->triangle_count(), 12u);
  EXPECT_EQ(rj.scene->unique_triangle_count(), 4u);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// A black quad in front of an emissive backdrop of radiance 1: what the camera sees through it is its transparency.
double seen_through(const std::string& mode, double alpha, double cutoff = 0.5) {
  GltfBuilder b;
  json front = {{"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, alpha}}, {"metallicFactor", 0}}},
                {"alphaMode", mode},
                {"alphaCutoff", cutoff}};
  int mf = b.material(front);
  int mb = b.material({{"emissiveFactor", {1, 1, 1}}});
  int quad, backdrop;
  square(b, 0, 0, 1, mf, &quad);
  square(b, 0, 0, 5, mb, &backdrop);
  b.node({{"mesh", quad}}, true);
  b.node({{"mesh", backdrop}, {"translation", {0, 0, -1}}}, true);
  std::string name = "alpha_" + mode + "_" + std::to_string(static_cast<int>(alpha * 100));
  b.write(fixture_dir(), name);
  json job = {{"kind", "scene"},
              {"scene",
               {{"gltf", name + ".gltf"},
                {"camera", {{"from", {0, 0, 3}}, {"to", {0, 0, 0}}, {"fov_deg", 10}}},
                {"environment", {{"color", 0}}}}},
              {"render", {{"width", 8}, {"height", 8}, {"spp", 256}, {"max_depth", 1}}}};
  return mean_green(render_job(job));
}

TEST(Gltf, AlphaMaskCutsOutAndBlendIsStochasticCoverage) {
  EXPECT_NEAR(seen_through("MASK", 0.3), 1.0, 1e-4);       // below the cutoff: not there
  EXPECT_NEAR(seen_through("MASK", 0.8), 0.0, 1e-4);       // above: opaque
  EXPECT_NEAR(seen_through("MASK", 0.3, 0.2), 0.0, 1e-4);  // the cutoff is the material's
  EXPECT_NEAR(seen_through("BLEND", 0.25), 0.75, 0.02);    // a quarter of the rays stop
  EXPECT_NEAR(seen_through("OPAQUE", 0.1), 0.0, 1e-4);     // alpha ignored when opaque
}

TEST(Gltf, MaskedOutSurfacesCastNoShadow) {
  for (double alpha : {0.3, 0.8}) {
    GltfBuilder b;
    b.node({{"mesh", floor_mesh(b)}}, true);
    int mq = b.material({{"pbrMetallicRoughness", {{"baseColorFactor", {1, 1, 1, alpha}}}}, {"alphaMode", "MASK"}});
    int quad;
    square(b, 0, 0, 1, mq, &quad);
    // Horizontal, half way between the light and the floor.
    b.node({{"mesh", quad}, {"translation", {0, 1, 0}}, {"rotation", {-std::sqrt(0.5), 0, 0, std::sqrt(0.5)}}}, true);
    b.doc["extensionsUsed"] = {"KHR_lights_punctual"};
    b.doc["extensions"] = {{"KHR_lights_punctual", {{"lights", {{{"type", "point"}, {"intensity", 10}}}}}}};
    b.node({{"translation", {0, 2, 0}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}, true);
    b.write(fixture_dir(), "shadow");
    json job = lit_floor_job("shadow.gltf");
    job["scene"]["camera"] = {{"from", {0.001, 0.5, 0}}, {"to", {0, 0, 0}}, {"up", {0, 0, -1}}, {"fov_deg", 2}};
    double lit = mean_green(render_job(job));
    if (alpha < 0.5)
      EXPECT_NEAR(lit, 0.5 / M_PI * 10 / 4, 0.01);  // unshadowed
    else
      EXPECT_LT(lit, 1e-6);
  }
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// A w x h PNG of 8-bit pixels of `channels` channels, encoded by OpenImageIO.
std::vector<unsigned char> png_pixels(int w, int h, int channels, const std::vector<unsigned char>& values) {
  std::vector<unsigned char> out;
  OIIO::Filesystem::IOVecOutput proxy(out);
  auto o = OIIO::ImageOutput::create("t.png");
  o->set_ioproxy(&proxy);
  OIIO::ImageSpec spec(w, h, channels, OIIO::TypeDesc::UINT8);
  if (channels == 2) spec.alpha_channel = 1;
  o->open("t.png", spec);
  o->write_image(OIIO::TypeDesc::UINT8, values.data());
  o->close();
  return out;
}
std::vector<unsigned char> png_rgba(int w, int h, const std::vector<unsigned char>& rgba) {
  return png_pixels(w, h, 4, rgba);
}

// An 8x8 texture of four 4x4 blocks: red, green / blue, white (row 0 at the top); alpha 0 in the white block.
// Blocks, not single texels, so that bilinear filtering at the quadrant centres sees one colour.
std::vector<unsigned char> quad_texture() {
  const unsigned char colours[4][4] = {{255, 0, 0, 255}, {0, 255, 0, 255}, {0, 0, 255, 255}, {255, 255, 255, 0}};
  std::vector<unsigned char> rgba;
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) rgba.insert(rgba.end(), colours[(y / 4) * 2 + x / 4], colours[(y / 4) * 2 + x / 4] + 4);
  return png_rgba(8, 8, rgba);
}

// A square facing +z with uv (0,0) at its top-left corner, seen straight on by an orthographic camera.
json textured_job(GltfBuilder& b, const json& material, const std::string& name) {
  int m = b.material(material);
  int mesh = b.textured_mesh({-1, 1, 0, 1, 1, 0, 1, -1, 0, -1, -1, 0}, {0, 0, 1, 0, 1, 1, 0, 1}, {0, 3, 2, 0, 2, 1}, m);
  b.node({{"mesh", mesh}}, true);
  b.write(fixture_dir(), name);
  return {{"kind", "scene"},
          {"scene",
           {{"gltf", name + ".gltf"},
            {"camera", {{"type", "orthographic"}, {"from", {0, 0, 5}}, {"to", {0, 0, 0}}, {"height", 2}}},
            {"environment", {{"color", {0.25, 0.25, 0.25}}}}}},
          {"render", {{"width", 32}, {"height", 32}, {"spp", 4}, {"max_depth", 0}}}};
}

TEST(GltfTextures, TexelColoursAppearWhereTheirUvsAre) {
  GltfBuilder b;
  int tex = b.texture_png(quad_texture(), {{"wrapS", 33071}, {"wrapT", 33071}, {"magFilter", 9728}});
  json mat = {{"emissiveFactor", {1, 1, 1}},
              {"emissiveTexture", {{"index", tex}}},
              {"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, 1}}}}};
  Rendered img = render_job(textured_job(b, mat, "texels"));
  // Quadrant centres: top-left red, top-right green, bottom-left blue, bottom-right white.
  Rgb tl = img.at(8, 8), tr = img.at(24, 8), bl = img.at(8, 24), br = img.at(24, 24);
  EXPECT_NEAR(tl.x, 1, 1e-3);
  EXPECT_NEAR(tl.y, 0, 1e-3);
  EXPECT_NEAR(tl.z, 0, 1e-3);
  EXPECT_NEAR(tr.x, 0, 1e-3);
  EXPECT_NEAR(tr.y, 1, 1e-3);
  EXPECT_NEAR(tr.z, 0, 1e-3);
  EXPECT_NEAR(bl.x, 0, 1e-3);
  EXPECT_NEAR(bl.y, 0, 1e-3);
  EXPECT_NEAR(bl.z, 1, 1e-3);
  EXPECT_NEAR(br.x, 1, 1e-3);
  EXPECT_NEAR(br.y, 1, 1e-3);
  EXPECT_NEAR(br.z, 1, 1e-3);
}

TEST(GltfTextures, TextureTransformOffsetsTheLookup) {
  GltfBuilder b;
  b.doc["extensionsUsed"] = {"KHR_texture_transform"};
  int tex = b.texture_png(quad_texture(), {{"wrapS", 10497}, {"wrapT", 10497}});
  json mat = {
      {"emissiveFactor", {1, 1, 1}},
      {"emissiveTexture", {{"index", tex}, {"extensions", {{"KHR_texture_transform", {{"offset", {0.5, 0}}}}}}}},
      {"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, 1}}}}};
  Rendered img = render_job(textured_job(b, mat, "offset"));
  // Shifted by half the texture horizontally (wrapping): the top-left quadrant now shows the green texel.
  EXPECT_NEAR(img.at(8, 8).y, 1, 1e-3);
  EXPECT_NEAR(img.at(8, 8).x, 0, 1e-3);
  EXPECT_NEAR(img.at(24, 24).z, 1, 1e-3);  // bottom-right shows blue
  EXPECT_NEAR(img.at(24, 24).x, 0, 1e-3);
}

// The rotation turns as the extension's matrix does (T * R * S, R = [cos sin; -sin cos]): by a quarter turn the
// texel at uv (s, t) = (v, -u) shows, so the blue quadrant (bottom-left of the texture) comes to the top-left.
TEST(GltfTextures, TextureTransformRotatesCounterClockwise) {
  GltfBuilder b;
  b.doc["extensionsUsed"] = {"KHR_texture_transform"};
  int tex = b.texture_png(quad_texture(), {{"wrapS", 10497}, {"wrapT", 10497}});
  json mat = {{"emissiveFactor", {1, 1, 1}},
              {"emissiveTexture",
               {{"index", tex}, {"extensions", {{"KHR_texture_transform", {{"rotation", 1.5707963267948966}}}}}}},
              {"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, 1}}}}};
  Rendered img = render_job(textured_job(b, mat, "rotation"));
  const Rgb tl = img.at(8, 8), tr = img.at(24, 8), br = img.at(24, 24), bl = img.at(8, 24);
  EXPECT_NEAR(tl.z, 1, 1e-3);  // blue
  EXPECT_NEAR(tl.x, 0, 1e-3);
  EXPECT_NEAR(tr.x, 1, 1e-3);  // red
  EXPECT_NEAR(tr.y, 0, 1e-3);
  EXPECT_NEAR(br.y, 1, 1e-3);  // green
  EXPECT_NEAR(br.x, 0, 1e-3);
  EXPECT_NEAR(bl.x, 1, 1e-3);  // white
  EXPECT_NEAR(bl.z, 1, 1e-3);
}

// KHR_materials_unlit: the base colour (factor times texture) is what the camera sees, exactly, whatever lights the
// scene and however far paths go.
TEST(GltfTextures, UnlitMaterialsShowTheirBaseColourExactly) {
  GltfBuilder b;
  b.doc["extensionsUsed"] = {"KHR_materials_unlit"};
  int tex = b.texture_png(quad_texture(), {{"wrapS", 33071}, {"wrapT", 33071}});
  json mat = {
      {"name", "flat"},
      {"pbrMetallicRoughness", {{"baseColorFactor", {0.2, 0.5, 0.8, 1}}, {"baseColorTexture", {{"index", tex}}}}},
      {"extensions", {{"KHR_materials_unlit", json::object()}}}};
  json job = textured_job(b, mat, "unlit");
  job["render"]["max_depth"] = 6;
  job["scene"]["environment"]["color"] = {2, 2, 2};
  Rendered img = render_job(job);
  const Rgb white = img.at(24, 24), red = img.at(8, 8);  // texels white and red, times the factor
  EXPECT_NEAR(white.x, 0.2, 1e-4);
  EXPECT_NEAR(white.y, 0.5, 1e-4);
  EXPECT_NEAR(white.z, 0.8, 1e-4);
  EXPECT_NEAR(red.x, 0.2, 1e-4);
  EXPECT_NEAR(red.y, 0, 1e-4);
  EXPECT_NEAR(red.z, 0, 1e-4);
}

// A rough transmissive pane of IOR 1 refracts nothing, so whatever its roughness it leaves a checker behind it sharp
// (the transmission lobe's roughness scales with clamp(2 ior - 2, 0, 1)).
TEST(GltfTextures, RoughTransmissionAtIor1StaysSharp) {
  const json pane = {{"type", "gltf_pbr"}, {"base_color", {1, 1, 1}}, {"metallic", 0},
                     {"roughness", 1},     {"transmission", 1},       {"ior", 1.0}};
  const json job = {{"kind", "scene"},
                    {"scene",
                     {{"materials",
                       {{"pane", pane},
                        {"checker",
                         {{"type", "lambert"},
                          {"albedo", {0, 0, 0}},
                          {"emission", {{"checker", {{"a", {1, 1, 1}}, {"b", {0, 0, 0}}, {"scale", 4}}}}}}}}},
                      {"objects",
                       {{{"shape", "rectangle"},
                         {"corner", {-2, -2, 0}},
                         {"edge1", {4, 0, 0}},
                         {"edge2", {0, 4, 0}},
                         {"material", "pane"}},
                        {{"shape", "rectangle"},
                         {"corner", {-1, -1, -1}},
                         {"edge1", {2, 0, 0}},
                         {"edge2", {0, 2, 0}},
                         {"material", "checker"}}}},
                      {"camera", {{"type", "orthographic"}, {"from", {0, 0, 5}}, {"to", {0, 0, 0}}, {"height", 2}}},
                      {"environment", {{"color", {0, 0, 0}}}}}},
                    {"render", {{"width", 32}, {"height", 32}, {"spp", 64}, {"max_depth", 4}}}};
  Rendered img = render_job(job);
  // Cells are 8 pixels wide: centres of neighbouring cells keep the checker's contrast.
  for (int y : {4, 12, 20, 28})
    for (int x : {4, 12, 20}) {
      const float a = img.at(x, y).y, b = img.at(x + 8, y).y;
      EXPECT_GT(std::max(a, b), 0.8f) << x << "," << y;
      EXPECT_LT(std::min(a, b), 0.1f) << x << "," << y;
    }
}

TEST(GltfTextures, BaseColourAlphaCutsOutUnderMask) {
  GltfBuilder b;
  int tex = b.texture_png(quad_texture(), {{"wrapS", 33071}, {"wrapT", 33071}});
  json mat = {{"emissiveFactor", {1, 1, 1}},
              {"emissiveTexture", {{"index", tex}}},
              {"alphaMode", "MASK"},
              {"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, 1}}, {"baseColorTexture", {{"index", tex}}}}}};
  Rendered img = render_job(textured_job(b, mat, "cutout"));
  EXPECT_NEAR(img.at(8, 8).x, 1, 1e-3);       // red texel: opaque
  EXPECT_NEAR(img.at(24, 24).x, 0.25, 1e-3);  // white texel has alpha 0: the environment shows through
  EXPECT_NEAR(img.at(24, 24).z, 0.25, 1e-3);
}

double srgb_decoded(int code) {
  const double v = code / 255.0;
  return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}

// Grey, grey and alpha, RGB and RGBA images, all in one asset (decoded side by side), each read as RGBA with its grey
// spread over red, green and blue and alpha 1 where it has none; each texture shows its own image.
TEST(GltfTextures, ImagesOfEveryChannelCountReadAsRgba) {
  struct Case {
    int channels;
    std::vector<unsigned char> texel;
    int r, g, b;  // expected sRGB codes, or -1 for the environment (cut out by alpha)
  };
  const std::vector<Case> cases = {{1, {128}, 128, 128, 128},
                                   {2, {200, 0}, -1, -1, -1},
                                   {2, {200, 255}, 200, 200, 200},
                                   {3, {255, 128, 0}, 255, 128, 0},
                                   {4, {0, 64, 255, 255}, 0, 64, 255}};
  for (size_t k = 0; k < cases.size(); ++k) {
    SCOPED_TRACE("image " + std::to_string(k));
    GltfBuilder b;
    std::vector<int> textures;
    for (const Case& c : cases) {
      std::vector<unsigned char> values;
      for (int i = 0; i < 4; ++i) values.insert(values.end(), c.texel.begin(), c.texel.end());  // 2x2 of one value
      textures.push_back(b.texture_png(png_pixels(2, 2, c.channels, values)));
    }
    json mat = {
        {"emissiveFactor", {1, 1, 1}},
        {"emissiveTexture", {{"index", textures[k]}}},
        {"alphaMode", "MASK"},
        {"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, 1}}, {"baseColorTexture", {{"index", textures[k]}}}}}};
    Rendered img = render_job(textured_job(b, mat, "channels" + std::to_string(k)));
    const Rgb got = img.at(16, 16);
    const Case& c = cases[k];
    if (c.r < 0) {
      EXPECT_NEAR(got.x, 0.25, 1e-3);  // the environment behind
      EXPECT_NEAR(got.z, 0.25, 1e-3);
    } else {
      EXPECT_NEAR(got.x, srgb_decoded(c.r), 2e-3);
      EXPECT_NEAR(got.y, srgb_decoded(c.g), 2e-3);
      EXPECT_NEAR(got.z, srgb_decoded(c.b), 2e-3);
    }
  }
}

// An 8-bit RGB JPEG of w x h, encoded by OpenImageIO (baseline or progressive).
std::vector<unsigned char> jpeg_rgb(int w, int h, bool progressive) {
  std::vector<unsigned char> out;
  OIIO::Filesystem::IOVecOutput proxy(out);
  auto o = OIIO::ImageOutput::create("t.jpg");
  o->set_ioproxy(&proxy);
  OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
  if (progressive) spec.attribute("jpeg:progressive", 1);
  o->open("t.jpg", spec);
  std::vector<unsigned char> rgb(static_cast<size_t>(w) * h * 3, 128);
  o->write_image(OIIO::TypeDesc::UINT8, rgb.data());
  o->close();
  return out;
}

// A scene checked rather than rendered (a job at submission) reads its images' headers only: pixels that cannot be
// decoded pass the check (the render fails on them later, naming the image), while a header that does not open or an
// image over the size limit is refused at once; JPEG headers included, read through libjpeg.
TEST(GltfHostile, ACheckedSceneReadsImageHeadersOnly) {
  std::vector<unsigned char> png = png_rgba(4, 4, std::vector<unsigned char>(64, 255));
  // Corrupt the compressed pixels: the IDAT chunk's data, after its length and type.
  const size_t idat = std::search(png.begin(), png.end(), std::begin("IDAT"), std::begin("IDAT") + 4) - png.begin();
  ASSERT_LT(idat + 12, png.size());
  for (size_t i = idat + 4; i < idat + 12; ++i) png[i] ^= 0x5a;
  GltfBuilder b = one_triangle();
  b.texture_png(png);
  b.write(fixture_dir(), "corrupt-pixels");
  Scene checked, rendered;
  GltfImportOptions check;
  check.headers_only = true;
  EXPECT_NO_THROW(import_gltf(fixture_dir() / "corrupt-pixels.gltf", "/scene/gltf", checked, check));
  expect_refused(fixture_dir() / "corrupt-pixels.gltf", "image 0 cannot be decoded");

  for (bool progressive : {false, true}) {
    SCOPED_TRACE(progressive ? "progressive JPEG" : "baseline JPEG");
    GltfBuilder j = one_triangle();
    j.texture_png(jpeg_rgb(40, 30, progressive));  // the data is sniffed, whatever the data URI's type says
    j.write(fixture_dir(), "jpeg");
    Scene scene;
    check.max_texture_pixels = 1200;
    EXPECT_NO_THROW(import_gltf(fixture_dir() / "jpeg.gltf", "/scene/gltf", scene, check));
    check.max_texture_pixels = 1199;
    try {
      import_gltf(fixture_dir() / "jpeg.gltf", "/scene/gltf", scene, check);
      ADD_FAILURE() << "a JPEG over the pixel limit passed the check";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("image 0 is too large (40x30 pixels)"), std::string::npos) << e.what();
    }
  }
  GltfBuilder garbage = one_triangle();
  garbage.texture_png({0xFF, 0xD8, 0xFF, 0x00, 1, 2, 3});  // a JPEG signature and nothing readable
  garbage.write(fixture_dir(), "garbage");
  Scene scene;
  check.max_texture_pixels = 1 << 20;
  EXPECT_THROW(import_gltf(fixture_dir() / "garbage.gltf", "/scene/gltf", scene, check), SceneError);
}

// A JPEG cut short (libjpeg would decode it with a warning only, the missing rows grey) or a PNG cut short (see
// png_complete) is refused when the scene is checked and when it is imported, naming the image; the whole image is
// taken.
TEST(GltfHostile, TruncatedJpegsAndPngsAreRefused) {
  struct Case {
    const char* name;
    std::vector<unsigned char> image;
  };
  const Case cases[] = {{"JPEG", jpeg_rgb(40, 30, false)},
                        {"JPEG", jpeg_rgb(40, 30, true)},
                        {"PNG", png_rgba(40, 30, std::vector<unsigned char>(40 * 30 * 4, 200))}};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    for (bool cut : {false, true}) {
      GltfBuilder b = one_triangle();
      b.texture_png(cut ? std::vector<unsigned char>(c.image.begin(), c.image.end() - 20) : c.image);
      b.write(fixture_dir(), "cut-image");
      for (bool headers_only : {true, false}) {
        Scene scene;
        GltfImportOptions options;
        options.headers_only = headers_only;
        if (!cut) {
          EXPECT_NO_THROW(import_gltf(fixture_dir() / "cut-image.gltf", "/scene/gltf", scene, options));
          continue;
        }
        try {
          import_gltf(fixture_dir() / "cut-image.gltf", "/scene/gltf", scene, options);
          ADD_FAILURE() << "a truncated image was accepted (headers only: " << headers_only << ")";
        } catch (const SceneError& e) {
          EXPECT_NE(std::string(e.what()).find(std::string("image 0 is a truncated ") + c.name), std::string::npos)
              << e.what();
        }
      }
    }
  }
}

// An image that does not decode, or is larger than allowed, fails the import naming the image, whichever of the
// images decoded at once fails.
TEST(GltfHostile, UndecodableAndOversizedImagesAreRefused) {
  const std::vector<unsigned char> good = png_rgba(4, 4, std::vector<unsigned char>(64, 255));
  {
    GltfBuilder b = one_triangle();
    b.texture_png(good);
    b.texture_png(good);
    b.texture_png({0x89, 'P', 'N', 'G', 1, 2, 3, 4});  // a PNG signature, then nothing decodable
    b.write(fixture_dir(), "undecodable");
    expect_refused(fixture_dir() / "undecodable.gltf", "image 2 cannot be decoded");
  }
  {
    // A KTX2 image (KHR_texture_basisu's container) named without the extension: said for what it is.
    GltfBuilder b = one_triangle();
    b.texture_png({0xAB, 'K', 'T', 'X', ' ', '2', '0', 0xBB, '\r', '\n', 0x1A, '\n', 0, 0, 0, 0});
    b.write(fixture_dir(), "ktx2");
    expect_refused(fixture_dir() / "ktx2.gltf", "image 0 is a KTX2 (Basis Universal) image");
  }
  {
    // An image in a file of its own is named by its URI, as the asset writes it.
    GltfBuilder b = one_triangle();
    b.texture_png(good);
    b.doc["images"][0]["uri"] = "broken.png";
    std::ofstream(fixture_dir() / "broken.png", std::ios::binary) << "not a PNG at all";
    b.write(fixture_dir(), "named-image");
    expect_refused(fixture_dir() / "named-image.gltf", "image \"broken.png\" cannot be decoded");
  }
  {
    GltfBuilder b = one_triangle();
    b.texture_png(good);
    b.write(fixture_dir(), "oversized");
    Scene scene;
    GltfImportOptions options;
    options.max_texture_pixels = 15;  // the image has 16
    try {
      import_gltf(fixture_dir() / "oversized.gltf", "/scene/gltf", scene, options);
      ADD_FAILURE() << "an image over the pixel limit was accepted";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("image 0 is too large (4x4 pixels)"), std::string::npos) << e.what();
    }
    options.max_texture_pixels = 16;
    EXPECT_NO_THROW(import_gltf(fixture_dir() / "oversized.gltf", "/scene/gltf", scene, options));
  }
}

std::vector<unsigned char> tilted_normal_png(double theta) {
  unsigned char nx = static_cast<unsigned char>(std::lround((0.5 + 0.5 * std::sin(theta)) * 255));
  unsigned char nz = static_cast<unsigned char>(std::lround((0.5 + 0.5 * std::cos(theta)) * 255));
  return png_rgba(1, 1, {nx, 128, nz, 255});
}

// Two single-channel textures over the same pixels and mapping (glTF's metallic in B, roughness in G) share one RGB
// lookup whose components equal each texture's own value bit for bit; other pairs do not.
TEST(Textures, ChannelsOfOneImageShareALookup) {
  auto pixels = std::make_shared<ImagePixels>();
  pixels->width = 5;
  pixels->height = 3;
  pixels->channels = 4;
  for (int i = 0; i < 5 * 3 * 4; ++i) pixels->data.push_back(static_cast<uint8_t>((i * 37 + 11) % 256));
  TextureMapping mapping;
  mapping.scale = Vec2(1.5f, 0.75f);
  mapping.rotation = 0.3f;
  auto metal = make_image_texture(pixels, false, 2, mapping), rough = make_image_texture(pixels, false, 1, mapping);
  int cm = -1, cr = -1;
  auto both = make_shared_channels_texture(metal.get(), rough.get(), &cm, &cr);
  ASSERT_TRUE(both);
  EXPECT_EQ(cm, 2);
  EXPECT_EQ(cr, 1);
  for (int i = 0; i < 200; ++i) {
    ShadingPoint sp;
    sp.uv = Vec2(std::fmod(i * 0.137f, 3.0f) - 1, std::fmod(i * 0.291f, 2.0f) - 0.5f);
    const Rgb t = both->eval(sp);
    EXPECT_EQ(t[cm], metal->eval(sp).x);
    EXPECT_EQ(t[cr], rough->eval(sp).x);
  }
  TextureMapping shifted = mapping;
  shifted.offset = Vec2(0.1f, 0);
  auto rough_shifted = make_image_texture(pixels, false, 1, shifted);
  EXPECT_FALSE(make_shared_channels_texture(metal.get(), rough_shifted.get(), &cm, &cr));
  auto other = std::make_shared<ImagePixels>(*pixels);  // equal values, other pixels
  EXPECT_FALSE(make_shared_channels_texture(metal.get(), make_image_texture(other, false, 1, mapping).get(), &cm, &cr));
  EXPECT_FALSE(make_shared_channels_texture(metal.get(), make_image_texture(pixels, true, 1, mapping).get(), &cm, &cr));
}

// A black and white checkerboard, one texel per square, as 8-bit sRGB pixels.
std::shared_ptr<ImagePixels> texel_checker(int w, int h) {
  auto pixels = std::make_shared<ImagePixels>();
  pixels->width = w;
  pixels->height = h;
  pixels->channels = 3;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) pixels->data.push_back((x + y) % 2 ? 255 : 0);
  return pixels;
}

// A footprint of zero reads the finest texels; wider footprints read mip levels that average linear light (black and
// white texels average to 0.5, not to the sRGB code 128, 0.22), odd sizes included, and the widest is the mean.
TEST(Textures, MipLevelsAverageLinearLight) {
  for (auto [w, h] : {std::pair{16, 16}, std::pair{15, 9}}) {
    auto tex = make_image_texture(texel_checker(w, h), true, -1, TextureMapping());
    ShadingPoint sp;
    sp.uv = Vec2((4 + 0.5f) / w, (5 + 0.5f) / h);  // the centre of texel (4, 5): white
    EXPECT_FLOAT_EQ(tex->eval(sp).y, 1.0f);
    sp.uv = Vec2((3 + 0.5f) / w, (5 + 0.5f) / h);
    EXPECT_FLOAT_EQ(tex->eval(sp).y, 0.0f);
    for (float texels : {2.0f, 2.8f, 4.0f, 64.0f}) {
      sp.uv_footprint = texels / std::sqrt(static_cast<float>(w * h));
      for (Vec2 uv : {Vec2(0.3f, 0.4f), Vec2(0.71f, 0.13f), Vec2(0.5f, 0.9f)}) {
        sp.uv = uv;
        // Odd sizes repeat an edge texel into a 2x2 average, which tilts a level's texels off the mean a little.
        EXPECT_NEAR(tex->eval(sp).y, 0.5f, w % 2 ? 0.13f : 0.01f) << w << "x" << h << ", " << texels << " texels";
      }
    }
  }
}

// Levels of a large image are made in parallel, rows split between threads: every texel of every level is made
// (a checker of single texels is grey at every level above the finest), and the texture's mean, which weighs light
// sources, is the mean of the texels whatever the split (odd sizes included).
TEST(Textures, LargeImagesAreMippedWhole) {
  auto tex = make_image_texture(texel_checker(1024, 1024), true, -1, TextureMapping());
  ShadingPoint sp;
  for (float texels : {2.0f, 4.0f, 16.0f}) {
    sp.uv_footprint = texels / 1024;
    for (int i = 0; i < 32; ++i)
      for (int j = 0; j < 32; ++j) {
        sp.uv = Vec2((i + 0.37f) / 32, (j + 0.61f) / 32);
        ASSERT_NEAR(tex->eval(sp).y, 0.5f, 0.01f) << texels << " texels at " << sp.uv.x << ", " << sp.uv.y;
      }
  }
  EXPECT_NEAR(tex->average().y, 0.5f, 1e-6f);

  auto noise = std::make_shared<ImagePixels>();
  noise->width = 1023;
  noise->height = 777;
  noise->channels = 4;
  std::mt19937 rng(7);
  double sum[3] = {0, 0, 0};
  for (int t = 0; t < noise->width * noise->height; ++t)
    for (int c = 0; c < 4; ++c) {
      const int code = static_cast<int>(rng() % 256);
      noise->data.push_back(static_cast<uint8_t>(code));
      if (c < 3) sum[c] += srgb_decoded(code);
    }
  const Rgb mean = make_image_texture(noise, true, -1, TextureMapping())->average();
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(mean[c], sum[c] / (1023.0 * 777.0), 1e-6) << "channel " << c;
}

// A finely textured surface seen from afar: each pixel covers about eleven texels of a one-texel checkerboard. With
// the ray cone's footprint every pixel's single sample is the board's mean, where point sampling would give each
// pixel one texel, black or white.
TEST(Textures, ADistantTextureIsFilteredOverThePixel) {
  auto png = png_rgba(256, 256, [] {
    std::vector<unsigned char> rgba;
    for (int y = 0; y < 256; ++y)
      for (int x = 0; x < 256; ++x)
        rgba.insert(rgba.end(), {0, static_cast<unsigned char>((x + y) % 2 ? 255 : 0), 0, 255});
    return rgba;
  }());
  std::ofstream(fixture_dir() / "fine.png", std::ios::binary)
      .write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  json job = {
      {"kind", "scene"},
      {"scene",
       {{"materials", {{"board", {{"type", "lambert"}, {"albedo", 0}, {"emission", {{"texture", "fine.png"}}}}}}},
        {"objects",
         {{{"shape", "rectangle"},
           {"corner", {-0.05, 0, 0.05}},
           {"edge1", {0.1, 0, 0}},
           {"edge2", {0, 0, -0.1}},
           {"material", "board"}}}},
        {"camera", {{"from", {0, 1, 0}}, {"to", {0, 0, 0}}, {"up", {0, 0, -1}}, {"fov_deg", 2}}}}},
      {"render", {{"width", 8}, {"height", 8}, {"spp", 1}, {"max_depth", 1}}}};
  Rendered r = render_job(job);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) EXPECT_NEAR(r.at(x, y).y, 0.5f, 0.05f) << x << ", " << y;
}

// Minified text is as sharp as a supersampled render: a panel of random glyphs (strokes two texels wide, about four
// texels a pixel) rendered at 64x64 with 16 samples a pixel, against the same view rendered at 256x256 and averaged
// down 4x4 (the pixel's box filter, supersampled). Each sample's cone covers its 1/16 share of the pixel
// (Camera::pixel_cone), not the whole pixel, which the box filter would blur a second time: RMSE 0.020 against
// 0.089 with whole-pixel cones (measured here, at these seeds; the bound between them allows for other noise).
TEST(Textures, MinifiedTextMatchesASupersampledRender) {
  const int n = 256;
  std::vector<unsigned char> rgba(static_cast<size_t>(n) * n * 4, 255);
  std::mt19937 rng(25);
  for (int cy = 0; cy + 16 <= n; cy += 16)
    for (int cx = 0; cx + 12 <= n; cx += 12)
      for (int gy = 0; gy < 7; ++gy)
        for (int gx = 0; gx < 5; ++gx) {
          if (rng() % 100 >= 45) continue;
          for (int d = 0; d < 4; ++d) {
            const size_t i = (static_cast<size_t>(cy + 2 * gy + d / 2) * n + cx + 2 * gx + d % 2) * 4;
            rgba[i] = rgba[i + 1] = rgba[i + 2] = 16;
          }
        }
  auto png = png_rgba(n, n, rgba);
  std::ofstream(fixture_dir() / "glyphs.png", std::ios::binary)
      .write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  auto render = [&](int size) {
    return render_job(
        {{"kind", "scene"},
         {"scene",
          {{"materials", {{"panel", {{"type", "lambert"}, {"albedo", 0}, {"emission", {{"texture", "glyphs.png"}}}}}}},
           {"objects",
            {{{"shape", "rectangle"},
              {"corner", {-1, -1, 0}},
              {"edge1", {2, 0, 0}},
              {"edge2", {0, 2, 0}},
              {"material", "panel"}}}},
           {"camera", {{"from", {0, 0, 2.75}}, {"to", {0, 0, 0}}, {"fov_deg", 40}}}}},
         {"render", {{"width", size}, {"height", size}, {"spp", 16}, {"max_depth", 1}, {"seed", size}}}});
  };
  const Rendered small = render(64), big = render(256);
  double sum2 = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      double ref = 0;
      for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) ref += big.at(4 * x + i, 4 * y + j).y / 16;
      sum2 += sqr(small.at(x, y).y - ref);
    }
  const double rmse = std::sqrt(sum2 / (64 * 64));
  EXPECT_LT(rmse, 0.035);
}

TEST(Textures, NormalMapTiltsTheShadingNormal) {
  // A constant normal map tilting the normal 60 degrees towards +u on a Lambert floor lit straight from above:
  // the reflected radiance falls to cos 60 = one half (the geometric normal is unchanged). Seen from 45 degrees
  // towards +u, where the tilted normal reflects the view above the floor (keep_reflection_above_surface leaves it).
  auto png = tilted_normal_png(M_PI / 3);
  std::ofstream(fixture_dir() / "tilt.png", std::ios::binary)
      .write(reinterpret_cast<const char*>(png.data()), png.size());
  double radiance[2];
  for (int with_map = 0; with_map < 2; ++with_map) {
    json floor = {{"type", "lambert"}, {"albedo", 0.5}};
    if (with_map) floor["normal_map"] = {{"texture", "tilt.png"}};
    json job = {{"kind", "scene"},
                {"scene",
                 {{"materials", {{"floor", floor}}},
                  {"objects",
                   {{{"shape", "rectangle"},
                     {"corner", {-10, 0, 10}},
                     {"edge1", {20, 0, 0}},
                     {"edge2", {0, 0, -20}},
                     {"material", "floor"}}}},
                  {"lights", {{{"type", "directional"}, {"direction", {0, -1, 0}}, {"irradiance", 3}}}},
                  {"camera", {{"from", {0.7, 0.7, 0}}, {"to", {0, 0, 0}}, {"up", {0, 0, -1}}, {"fov_deg", 2}}}}},
                {"render", {{"width", 8}, {"height", 8}, {"spp", 4}, {"max_depth", 1}}}};
    radiance[with_map] = mean_green(render_job(job));
  }
  EXPECT_NEAR(radiance[0], 0.5 / M_PI * 3, 0.01);
  // 8-bit quantisation of the map moves the cosine by well under 1%.
  EXPECT_NEAR(radiance[1] / radiance[0], 0.5, 0.01);
}

TEST(GltfTextures, NormalTextureIsApplied) {
  double radiance[2];
  for (int with_map = 0; with_map < 2; ++with_map) {
    GltfBuilder b;
    int tex = b.texture_png(tilted_normal_png(M_PI / 3));
    json mat = {{"pbrMetallicRoughness",
                 {{"baseColorFactor", {0.5, 0.5, 0.5, 1}}, {"metallicFactor", 0}, {"roughnessFactor", 1}}}};
    if (with_map) mat["normalTexture"] = {{"index", tex}, {"scale", 1}};
    int m = b.material(mat);
    int mesh = b.textured_mesh({-10, 0, -10, 10, 0, -10, 10, 0, 10, -10, 0, 10}, {0, 0, 1, 0, 1, 1, 0, 1},
                               {0, 2, 1, 0, 3, 2}, m);
    b.node({{"mesh", mesh}}, true);
    b.doc["extensionsUsed"] = {"KHR_lights_punctual"};
    b.doc["extensions"] = {{"KHR_lights_punctual", {{"lights", {{{"type", "directional"}, {"intensity", 3}}}}}}};
    b.node({{"rotation", {-std::sqrt(0.5), 0, 0, std::sqrt(0.5)}},
            {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}},
           true);
    b.write(fixture_dir(), "normaltex");
    json job = {{"kind", "scene"},
                {"scene",
                 {{"gltf", "normaltex.gltf"},
                  {"camera", {{"from", {0.7, 0.7, 0}}, {"to", {0, 0, 0}}, {"up", {0, 0, -1}}, {"fov_deg", 2}}},
                  {"environment", {{"color", 0}}}}},
                {"render", {{"width", 8}, {"height", 8}, {"spp", 16}, {"max_depth", 1}}}};
    radiance[with_map] = mean_green(render_job(job));
  }
  // A rough dielectric is not Lambertian, but tilting its normal 60 degrees away from the light darkens it a lot.
  EXPECT_GT(radiance[0], 0);
  EXPECT_LT(radiance[1] / radiance[0], 0.7);
}

// A white furnace (environment 1 everywhere): a smooth white metal sphere reflects it back, 1 at every pixel but for
// the single-scattering lobe's small loss. A strong normal map (every normal tilted 60 degrees along the tangent)
// must not change that: where the tilted normal would reflect a view direction into the sphere, the normal is bent
// so the reflection stays above the surface (keep_reflection_above_surface), where paths died before and left black
// crescents. The mean over the sphere's pixels, with and without the map, within 4 standard errors measured from the
// pixels' spread (and 1 %), and no pixel below one half.
TEST(Textures, StrongNormalMapsOnMetalsKeepTheirEnergyInAWhiteFurnace) {
  auto png = tilted_normal_png(M_PI / 3);
  std::ofstream(fixture_dir() / "tilt60.png", std::ios::binary)
      .write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  const int size = 64;
  double mean[2], se[2], lowest[2];
  for (int with_map = 0; with_map < 2; ++with_map) {
    json metal = {{"type", "gltf_pbr"}, {"base_color", 1}, {"metallic", 1}, {"roughness", 0}};
    if (with_map) metal["normal_map"] = {{"texture", "tilt60.png"}};
    json job = {{"kind", "scene"},
                {"scene",
                 {{"materials", {{"metal", metal}}},
                  {"objects", {{{"shape", "sphere"}, {"center", {0, 0, 0}}, {"radius", 1}, {"material", "metal"}}}},
                  {"camera", {{"type", "orthographic"}, {"from", {0, 0, 5}}, {"to", {0, 0, 0}}, {"height", 2.2}}},
                  {"environment", {{"color", 1}}}}},
                {"render", {{"width", size}, {"height", size}, {"spp", 8}, {"max_depth", 16}}}};
    Rendered img = render_job(job);
    // Pixels whose whole footprint lies on the sphere (the camera sees x, y in [-1.1, 1.1]).
    double sum = 0, sum2 = 0;
    int n = 0;
    lowest[with_map] = 1e9;
    for (int y = 0; y < size; ++y)
      for (int x = 0; x < size; ++x) {
        const double px = ((x + 0.5) / size * 2 - 1) * 1.1, py = ((y + 0.5) / size * 2 - 1) * 1.1;
        if (std::hypot(px, py) > 0.95) continue;
        const double v = img.at(x, y).y;
        sum += v;
        sum2 += v * v;
        lowest[with_map] = std::min(lowest[with_map], v);
        ++n;
      }
    mean[with_map] = sum / n;
    se[with_map] = std::sqrt(std::max(0.0, sum2 / n - mean[with_map] * mean[with_map]) / n);
  }
  EXPECT_GT(mean[0], 0.95);  // the unmapped sphere: the furnace reflected
  EXPECT_NEAR(mean[1], mean[0], 4 * std::hypot(se[0], se[1]) + 0.01) << "se " << se[0] << ", " << se[1];
  EXPECT_GT(lowest[1], 0.5);
}

// KHR_materials_clearcoat's clearcoatNormalTexture tilts the coat's own normal: a floor whose base reflects
// nothing (black, specularFactor 0) under a smooth coat, seen from straight above, mirrors a bright panel 40 degrees
// off the vertical only when the coat's normal is tilted 20 degrees towards it (the base's normal stays put). About
// the coat's Fresnel reflectance, Schlick(0.04, cos 20) = 0.04, times the panel's radiance 1, with the map; nothing
// without it.
TEST(GltfTextures, ClearcoatNormalTextureTiltsTheCoat) {
  double radiance[2];
  for (int with_map = 0; with_map < 2; ++with_map) {
    GltfBuilder b;
    b.doc["extensionsUsed"] = {"KHR_materials_clearcoat", "KHR_materials_specular"};
    int tex = b.texture_png(tilted_normal_png(20 * M_PI / 180));
    json coat = {{"clearcoatFactor", 1}, {"clearcoatRoughnessFactor", 0}};
    if (with_map) coat["clearcoatNormalTexture"] = {{"index", tex}};
    int m = b.material(
        {{"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, 1}}, {"metallicFactor", 0}, {"roughnessFactor", 1}}},
         {"extensions", {{"KHR_materials_clearcoat", coat}, {"KHR_materials_specular", {{"specularFactor", 0}}}}}});
    int floor = b.textured_mesh({-10, 0, -10, 10, 0, -10, 10, 0, 10, -10, 0, 10}, {0, 0, 1, 0, 1, 1, 0, 1},
                                {0, 2, 1, 0, 3, 2}, m);
    b.node({{"mesh", floor}}, true);
    // The panel: 10 wide, 20 away towards (sin 40, cos 40, 0), turned to face the floor's centre.
    const double a = 40 * M_PI / 180, c = std::cos(a), sn = std::sin(a);
    int light = b.material({{"emissiveFactor", {1, 1, 1}},
                            {"doubleSided", true},
                            {"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, 1}}}}});
    int panel;
    square(b, 0, 0, 5, light, &panel);
    b.node({{"mesh", panel},
            {"translation", {20 * sn, 20 * c, 0}},
            {"rotation", {c * std::sqrt(0.5), -sn * std::sqrt(0.5), 0, std::sqrt(0.5)}}},
           true);
    b.write(fixture_dir(), "coatnormal");
    json job = {
        {"kind", "scene"},
        {"scene",
         {{"gltf", "coatnormal.gltf"},
          {"camera",
           {{"type", "orthographic"}, {"from", {0, 5, 0}}, {"to", {0, 0, 0}}, {"up", {0, 0, -1}}, {"height", 0.5}}},
          {"environment", {{"color", 0}}}}},
        {"render", {{"width", 8}, {"height", 8}, {"spp", 16}, {"max_depth", 2}}}};
    radiance[with_map] = mean_green(render_job(job));
  }
  EXPECT_LT(radiance[0], 0.004);
  EXPECT_NEAR(radiance[1], 0.04, 0.01);
}

// An axis-aligned box of half-extents (hx, hy, hz) centred at the origin, each face wound counter-clockwise seen from
// outside (its own four vertices, so the faces are flat).
int box_mesh(GltfBuilder& b, float hx, float hy, float hz, int material) {
  std::vector<float> pos;
  std::vector<uint16_t> idx;
  const float h[3] = {hx, hy, hz};
  for (int axis = 0; axis < 3; ++axis)
    for (float sign : {1.0f, -1.0f}) {
      // u x v = the outward normal (sign along `axis`).
      const int ua = (axis + 1) % 3, va = (axis + 2) % 3;
      const uint16_t first = static_cast<uint16_t>(pos.size() / 3);
      for (auto [su, sv] : {std::pair{-1, -1}, {1, -1}, {1, 1}, {-1, 1}}) {
        float p[3];
        p[axis] = sign * h[axis];
        p[ua] = su * sign * h[ua];
        p[va] = sv * h[va];
        pos.insert(pos.end(), {p[0], p[1], p[2]});
      }
      idx.insert(idx.end(), {first, static_cast<uint16_t>(first + 1), static_cast<uint16_t>(first + 2), first,
                             static_cast<uint16_t>(first + 2), static_cast<uint16_t>(first + 3)});
    }
  return b.mesh(pos, idx, material);
}

// The sideways shift of what is seen through a smooth slab of index n and thickness d turned by theta about the
// vertical, looking along -z: t.x L, with t the refracted direction and L = d / cos(theta_t) the path inside (the ray
// leaves parallel to how it came). Snell's law in vector form (Dutre, Bala & Bekaert, Advanced Global Illumination,
// 2nd ed., 2.5.3): d = -z enters through the face of normal (sin theta, 0, cos theta), t = eta d + (eta cos_i -
// cos_t) n with eta = 1 / n, and d.x = 0.
double slab_shift(double theta, double n, double thickness) {
  const double nx = std::sin(theta), cos_i = std::cos(theta), eta = 1 / n;
  const double cos_t = std::sqrt(1 - eta * eta * (1 - cos_i * cos_i));
  return thickness * (eta * cos_i - cos_t) * nx / cos_t;
}

// A glTF glass slab (extensions `glass` on a white, smooth, fully transmitting material), `half_width` wide on each
// side, 4 high and `thickness` thick, turned by theta about the vertical, hiding a bright vertical line 0.06 wide at x
// = 0 behind it, seen by an orthographic camera looking along -z whose view is `view_height` high.
Rendered render_line_behind_slab(const json& glass, double theta, float half_width, double thickness,
                                 double view_height, int width, int height, uint32_t spp) {
  GltfBuilder b;
  for (const auto& [name, value] : glass.items()) b.doc["extensionsUsed"].push_back(name);
  int slab = b.material(
      {{"pbrMetallicRoughness", {{"baseColorFactor", {1, 1, 1, 1}}, {"metallicFactor", 0}, {"roughnessFactor", 0}}},
       {"extensions", glass}});
  int line = b.material({{"emissiveFactor", {1, 1, 1}}, {"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, 1}}}}});
  b.node({{"mesh", box_mesh(b, half_width, 2, static_cast<float>(thickness / 2), slab)},
          {"rotation", {0, std::sin(theta / 2), 0, std::cos(theta / 2)}}},
         true);
  b.node({{"mesh", box_mesh(b, 0.03f, 2, 0.01f, line)}, {"translation", {0, 0, -thickness - 2}}}, true);
  b.write(fixture_dir(), "slab");
  json job = {{"kind", "scene"},
              {"scene",
               {{"gltf", "slab.gltf"},
                {"camera", {{"type", "orthographic"}, {"from", {0, 0, 6}}, {"to", {0, 0, 0}}, {"height", view_height}}},
                {"environment", {{"color", 0}}}}},
              {"render", {{"width", width}, {"height", height}, {"spp", spp}, {"max_depth", 8}}}};
  return render_job(job);
}

// The centroid column of channel c over columns [x0, x1] of all rows.
double centroid_column(const Rendered& img, int c, int x0, int x1) {
  double sum = 0, moment = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = std::max(0, x0); x <= std::min(img.width - 1, x1); ++x) {
      sum += img.at(x, y)[c];
      moment += img.at(x, y)[c] * (x + 0.5);
    }
  return sum > 0 ? moment / sum : -1;
}

// KHR_materials_volume with a thicknessFactor above 0 makes a solid dielectric: a smooth glass slab (ior 1.5, 1 thick)
// turned 45 degrees shifts what is seen through it sideways by Snell's law (slab_shift). A thin wall (thickness 0)
// shifts nothing. The column where the line shows is compared.
TEST(GltfTransmission, SolidGlassRefractsBySnellsLaw) {
  const double theta = M_PI / 4, ior = 1.5;
  const double shift = slab_shift(theta, ior, 1);
  const int width = 512, height = 128;  // 2 units of height: 64 pixels per unit, x in [-4, 4]
  auto column_of = [&](double x) { return (x + 4) / 8 * width; };
  double found[2];
  for (int solid = 0; solid < 2; ++solid) {
    const json glass = {{"KHR_materials_transmission", {{"transmissionFactor", 1}}},
                        {"KHR_materials_ior", {{"ior", ior}}},
                        {"KHR_materials_volume", {{"thicknessFactor", solid ? 1.0 : 0.0}}}};
    const Rendered img = render_line_behind_slab(glass, theta, 2, 1, 2, width, height, 16);
    // The brightest column (summed over the rows), refined by the centroid of the columns around it.
    std::vector<double> col(width, 0.0);
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) col[x] += img.at(x, y).y;
    const int peak = static_cast<int>(std::max_element(col.begin(), col.end()) - col.begin());
    found[solid] = centroid_column(img, 1, peak - 4, peak + 4);
    ASSERT_GT(found[solid], 0) << "solid " << solid;
  }
  // The line is at x = 0; through the slab it shows where the camera ray lands on it: at x0 with x0 + shift = 0.
  EXPECT_NEAR(found[0], column_of(0), 1.0);
  EXPECT_NEAR(found[1], column_of(-shift), 1.0);
  EXPECT_GT(std::abs(column_of(-shift) - column_of(0)), 15);  // the test can tell the two apart
}

// A smooth (roughness 0) thin-walled pane of KHR_materials_transmission lets light through unbent, so what is seen
// through it is what is seen without it, only dimmer: a checker texture 4 units behind the pane is as sharp through it
// as without it (as in the Khronos sample TransmissionTest, whose smooth thin-walled spheres show the checker behind
// them sharp). Compared: each image divided by its mean, then the root mean square of their difference against the
// checker's own contrast. A lobe or a texture footprint widened by the pane (a roughness floor too high, a ray cone
// spread by a near-specular lobe) blurs the squares' edges and raises it.
TEST(GltfTransmission, ASmoothThinWallDoesNotBlurWhatIsBehindIt) {
  constexpr int kTexels = 512, kSquare = 32;
  std::vector<unsigned char> rgba;
  for (int y = 0; y < kTexels; ++y)
    for (int x = 0; x < kTexels; ++x) {
      const unsigned char v = ((x / kSquare + y / kSquare) % 2) ? 230 : 25;
      rgba.insert(rgba.end(), {v, v, v, 255});
    }
  const std::vector<unsigned char> checker = png_rgba(kTexels, kTexels, rgba);
  Rendered images[2];
  for (int pane = 0; pane < 2; ++pane) {
    GltfBuilder b;
    b.doc["extensionsUsed"] = {"KHR_materials_transmission"};
    const int tex = b.texture_png(checker);
    const int backdrop = b.material({{"emissiveFactor", {1, 1, 1}},
                                     {"emissiveTexture", {{"index", tex}}},
                                     {"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, 1}}}}});
    b.node({{"mesh", b.textured_mesh({-2, 2, -4, 2, 2, -4, 2, -2, -4, -2, -2, -4}, {0, 0, 1, 0, 1, 1, 0, 1},
                                     {0, 3, 2, 0, 2, 1}, backdrop)}},
           true);
    if (pane) {
      const int glass = b.material(
          {{"pbrMetallicRoughness", {{"baseColorFactor", {1, 1, 1, 1}}, {"metallicFactor", 0}, {"roughnessFactor", 0}}},
           {"doubleSided", true},
           {"extensions", {{"KHR_materials_transmission", {{"transmissionFactor", 1}}}}}});
      b.node({{"mesh", b.mesh({-1, 1, 0, 1, 1, 0, 1, -1, 0, -1, -1, 0}, {0, 3, 2, 0, 2, 1}, glass)}}, true);
    }
    b.write(fixture_dir(), "pane");
    const json job = {{"kind", "scene"},
                      {"scene",
                       {{"gltf", "pane.gltf"},
                        {"camera", {{"type", "perspective"}, {"from", {0, 0, 1}}, {"to", {0, 0, 0}}, {"fov_deg", 40}}},
                        {"environment", {{"color", 0}}}}},
                      {"render", {{"width", 256}, {"height", 256}, {"spp", 16}, {"max_depth", 4}}}};
    images[pane] = render_job(job);
  }
  auto mean = [](const Rendered& img) {
    double sum = 0;
    for (size_t i = 0; i < img.rgb.size(); i += 3) sum += img.rgb[i + 1];
    return sum / static_cast<double>(img.rgb.size() / 3);
  };
  const double without = mean(images[0]), through = mean(images[1]);
  ASSERT_GT(through, 0.5 * without);  // the pane lets most of the light through
  double diff2 = 0, contrast2 = 0;
  for (size_t i = 1; i < images[0].rgb.size(); i += 3) {
    const double a = images[0].rgb[i] / without, b = images[1].rgb[i] / through;
    diff2 += (a - b) * (a - b);
    contrast2 += (a - 1) * (a - 1);
  }
  const double relative = std::sqrt(diff2 / contrast2);
  EXPECT_LT(relative, 0.1) << "the checker seen through the pane differs from the checker by " << relative
                           << " of its contrast";
}

// KHR_materials_dispersion parts the colours by Snell's law at each wavelength: a slab as above, 3 thick, of dispersion
// 4 (V_d = 5), shows the line behind it as a spectrum. Each channel of the image is the line's shift at every
// wavelength weighted by that channel's weight (renderer/spectrum.h), so each channel's centroid column is predicted
// from the weights and Snell's law alone; without the dispersion (or with the wavelength not reaching the BSDF, or
// its weight not reaching the path) the three channels' lines coincide.
TEST(GltfTransmission, DispersiveGlassPartsColoursBySnellsLawAtEachWavelength) {
  const double theta = M_PI / 4, ior = 1.5, dispersion = 4, thickness = 3;
  const int width = 1024, height = 32;  // half a unit of height: 64 pixels per unit; x in [-8, 8]
  auto column_of = [&](double x) { return (x + 8) / 16 * width; };
  // The predicted column of each channel: the weight-averaged column of the line seen at each 1 nm of wavelength.
  Vec3 predicted(0), total(0);
  for (float nm = spectrum::kMinNm + 0.5f; nm < spectrum::kMaxNm; nm += 1) {
    const Rgb w = spectrum::channel_weight(nm);
    const double column = column_of(-slab_shift(theta, spectrum::dispersive_ior(ior, dispersion, nm), thickness));
    predicted += w * static_cast<float>(column);
    total += w;
  }
  predicted = Vec3(predicted.x / total.x, predicted.y / total.y, predicted.z / total.z);
  ASSERT_GT(predicted.z - predicted.x, 5);  // blue bends most, so its line is seen furthest right: the test can tell

  Vec3 found[2];
  for (int dispersive = 0; dispersive < 2; ++dispersive) {
    const json glass = {{"KHR_materials_transmission", {{"transmissionFactor", 1}}},
                        {"KHR_materials_ior", {{"ior", ior}}},
                        {"KHR_materials_volume", {{"thicknessFactor", thickness}}},
                        {"KHR_materials_dispersion", {{"dispersion", dispersive ? dispersion : 0.0}}}};
    const Rendered img = render_line_behind_slab(glass, theta, 4, thickness, 0.5, width, height, 64);
    // Each channel's centroid column over the pixels around the line (the slab's shift at 1.5, +-32 columns).
    const int centre = static_cast<int>(column_of(-slab_shift(theta, ior, thickness)));
    for (int c = 0; c < 3; ++c) {
      found[dispersive][c] = static_cast<float>(centroid_column(img, c, centre - 32, centre + 32));
      ASSERT_GT(found[dispersive][c], 0) << "channel " << c;
    }
  }
  std::printf(
      "line's column, red green blue: predicted %.2f %.2f %.2f, found %.2f %.2f %.2f (without dispersion %.2f %.2f "
      "%.2f)\n",
      predicted.x, predicted.y, predicted.z, found[1].x, found[1].y, found[1].z, found[0].x, found[0].y, found[0].z);
  // Without dispersion the channels coincide; with it each lands where its wavelengths put it.
  EXPECT_NEAR(found[0].x, found[0].z, 0.25);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(found[1][c], predicted[c], 0.3) << "channel " << c;
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Camera rays go to Embree in packets (Accel::intersect_packet). Each ray of a packet must find what it finds alone,
// through instances (one mirrored), alpha-masked and blended triangles (filter functions) and spheres, whatever the
// packet's other rays do and however many of its lanes are in use.
TEST(Accel, PacketHitsAreTheSingleRayHits) {
  GltfBuilder b;
  int grey = b.material({{"pbrMetallicRoughness", {{"baseColorFactor", {0.7, 0.7, 0.7, 1}}}}});
  std::vector<float> pos = {-0.5f, -0.5f, 0.5f, 0.5f, -0.5f, 0.5f, 0.5f, 0.5f, 0.5f,  -0.5f, 0.5f, 0.5f,
                            -0.5f, 0.5f,  0.5f, 0.5f, 0.5f,  0.5f, 0.5f, 0.5f, -0.5f, -0.5f, 0.5f, -0.5f};
  std::vector<uint16_t> idx = {0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7};
  int cube = b.mesh(pos, idx, grey);
  json scales = {{1, 1, 1}, {-1, 1, 1}, {1, 2, 1}};
  for (int i = 0; i < 3; ++i)
    b.node({{"mesh", cube}, {"translation", {-2.0 + 2 * i, 0, 0}}, {"scale", scales[i]}}, true);
  int masked = b.material({{"pbrMetallicRoughness", {{"baseColorFactor", {1, 1, 1, 0.3}}}}, {"alphaMode", "MASK"}});
  int blended = b.material({{"pbrMetallicRoughness", {{"baseColorFactor", {1, 1, 1, 0.5}}}}, {"alphaMode", "BLEND"}});
  int qm, qb;
  square(b, -1, 0, 1.5f, masked, &qm);
  square(b, 1, 0, 1.5f, blended, &qb);
  b.node({{"mesh", qm}, {"translation", {0, 0, 1.5}}}, true);
  b.node({{"mesh", qb}, {"translation", {0, 0, 1.2}}}, true);
  b.write(fixture_dir(), "packets");
  json doc = {{"gltf", "packets.gltf"},
              {"objects",
               {{{"shape", "sphere"}, {"center", {0, 1.5, 0}}, {"radius", 0.6}, {"material", "ball"}},
                {{"shape", "sphere"}, {"center", {1.5, -1, 0.5}}, {"radius", 0.3}, {"material", "ball"}}}},
              {"materials", {{"ball", {{"type", "lambert"}}}}},
              {"camera", {{"from", {0, 1, 6}}, {"to", {0, 0, 0}}, {"fov_deg", 50}}}};
  SceneLoadOptions opts;
  opts.asset_root = fixture_dir();
  std::shared_ptr<Scene> scene = load_scene(doc, "/scene", opts);
  ASSERT_FALSE(scene->instances.empty());

  std::mt19937 rng(7);
  std::uniform_real_distribution<float> uni(0, 1);
  const Camera camera(scene->camera, 64, 64);
  int compared = 0, hits = 0, sphere_hits = 0, instance_hits = 0;
  auto check_packet = [&](const std::vector<Ray>& rays) {
    RayHit packet[Accel::kPacketSize];
    bool found[Accel::kPacketSize];
    scene->accel().intersect_packet(rays.data(), static_cast<int>(rays.size()), packet, found);
    for (size_t i = 0; i < rays.size(); ++i) {
      RayHit single;
      const bool single_found = scene->accel().intersect(rays[i], &single);
      ASSERT_EQ(found[i], single_found) << "ray " << i;
      ++compared;
      if (!single_found) continue;
      ++hits;
      sphere_hits += single.is_sphere;
      instance_hits += single.instance != kNoInstance;
      EXPECT_EQ(packet[i].is_sphere, single.is_sphere);
      EXPECT_EQ(packet[i].object, single.object);
      EXPECT_EQ(packet[i].instance, single.instance);
      EXPECT_EQ(packet[i].prim_id, single.prim_id);
      // Embree's packet kernels may round differently from its single-ray ones (spheres), never more than that.
      EXPECT_NEAR(packet[i].t, single.t, 1e-5f * single.t);
      EXPECT_NEAR(packet[i].u, single.u, 1e-4f);
      EXPECT_NEAR(packet[i].v, single.v, 1e-4f);
    }
  };
  // Camera rays of neighbouring pixels, as the renderer sends them, in packets of every size from 1 to 8.
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64;) {
      const int n = 1 + (x + y) % Accel::kPacketSize;
      std::vector<Ray> rays;
      for (int i = 0; i < n && x < 64; ++i, ++x)
        rays.push_back(camera.generate_ray(Vec2(x + uni(rng), y + uni(rng)), Vec2(0.5f, 0.5f)));
      check_packet(rays);
    }
  // Incoherent rays from anywhere in the scene's bounds in any direction, full packets.
  const Bounds& bounds = scene->bounds();
  for (int p = 0; p < 512; ++p) {
    std::vector<Ray> rays(Accel::kPacketSize);
    for (Ray& r : rays) {
      r.origin = bounds.lo + (bounds.hi - bounds.lo) * Vec3(uni(rng), uni(rng), uni(rng));
      r.dir = sample_uniform_sphere(Vec2(uni(rng), uni(rng)));
    }
    check_packet(rays);
  }
  // The scene was hit in every way the test is about.
  EXPECT_GT(hits, compared / 4);
  EXPECT_GT(sphere_hits, 50);
  EXPECT_GT(instance_hits, 50);
}

}  // namespace
}  // namespace tessera
