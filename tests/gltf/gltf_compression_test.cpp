// Compressed glTF geometry: a mesh written compressed (KHR_draco_mesh_compression through Draco's encoder,
// EXT_meshopt_compression through meshoptimizer's) imports as the same triangles as its uncompressed twin; malformed
// streams and misuse of meshopt's fallback buffers are refused with a SceneError.
#include <gtest/gtest.h>

#include <draco/compression/encode.h>
#include <draco/mesh/triangle_soup_mesh_builder.h>
#include <meshoptimizer.h>

#include <unistd.h>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <random>

#include "renderer/gltf/loader.h"
#include "renderer/job.h"
#include "renderer/scene_error.h"
#include "renderer/session.h"
#include "renderer/thread_pool.h"
#include "tests/renderer/gltf_fixture.h"

namespace tessera {
namespace {

using nlohmann::json;
using test::GltfBuilder;

std::filesystem::path fixture_dir() {
  return test::gltf_fixture_dir();
}

// A curved grid of n x n vertices with normals: positions, normals, triangle indices.
struct Grid {
  std::vector<float> positions, normals;
  std::vector<uint16_t> indices;
};
Grid grid(int n) {
  Grid g;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const float x = i * 0.25f - 0.5f, y = j * 0.25f - 0.5f, z = 0.3f * std::sin(3.0f * x) * std::cos(2.0f * y);
      g.positions.insert(g.positions.end(), {x, y, z});
      const float nx = -0.9f * std::cos(3.0f * x) * std::cos(2.0f * y),
                  ny = 0.6f * std::sin(3.0f * x) * std::sin(2.0f * y);
      const float len = std::sqrt(nx * nx + ny * ny + 1);
      g.normals.insert(g.normals.end(), {nx / len, ny / len, 1 / len});
    }
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const uint16_t a = static_cast<uint16_t>(j * n + i), b = a + 1, c = a + n, d = c + 1;
      g.indices.insert(g.indices.end(), {a, b, d, a, d, c});
    }
  return g;
}

// The scene's triangles as position and normal triples, each rotated to start at its least vertex (winding kept)
// and sorted: equal for two imports of the same triangles whatever their vertex and face order.
using Corner = std::array<float, 6>;
using Triangle = std::array<Corner, 3>;
std::vector<Triangle> triangles(const Scene& scene) {
  std::vector<Triangle> out;
  for (const Mesh& m : scene.meshes)
    for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
      Triangle tri;
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = m.indices[t + k];
        const Vec3 p = m.positions[v], nn = m.normals.empty() ? Vec3() : m.normals[v];
        tri[k] = {p.x, p.y, p.z, nn.x, nn.y, nn.z};
      }
      std::rotate(tri.begin(), std::min_element(tri.begin(), tri.end()), tri.end());
      out.push_back(tri);
    }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<Triangle> import_triangles(const std::filesystem::path& path) {
  Scene scene;
  import_gltf(path, "/scene/gltf", scene, {});
  return triangles(scene);
}

// The uncompressed twin: the grid as plain accessors.
std::filesystem::path write_plain(const Grid& g, const std::string& name) {
  GltfBuilder b;
  b.node({{"mesh", b.mesh(g.positions, g.indices, -1, g.normals)}}, true);
  return b.write(fixture_dir(), name);
}

// The grid as a Draco mesh (Draco's own encoder, lossless: no quantization), its bytes.
std::vector<unsigned char> draco_bytes(const Grid& g, int* position_id, int* normal_id, int method) {
  draco::TriangleSoupMeshBuilder builder;
  const int faces = static_cast<int>(g.indices.size() / 3);
  builder.Start(faces);
  const int pos = builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  const int nor = builder.AddAttribute(draco::GeometryAttribute::NORMAL, 3, draco::DT_FLOAT32);
  for (int f = 0; f < faces; ++f) {
    const float* p[3];
    const float* n[3];
    for (int k = 0; k < 3; ++k) {
      p[k] = &g.positions[3 * g.indices[3 * f + k]];
      n[k] = &g.normals[3 * g.indices[3 * f + k]];
    }
    builder.SetAttributeValuesForFace(pos, draco::FaceIndex(f), p[0], p[1], p[2]);
    builder.SetAttributeValuesForFace(nor, draco::FaceIndex(f), n[0], n[1], n[2]);
  }
  std::unique_ptr<draco::Mesh> mesh = builder.Finalize();
  EXPECT_TRUE(mesh);
  *position_id = static_cast<int>(mesh->attribute(pos)->unique_id());
  *normal_id = static_cast<int>(mesh->attribute(nor)->unique_id());
  draco::Encoder encoder;
  encoder.SetEncodingMethod(method);
  draco::EncoderBuffer out;
  const draco::Status status = encoder.EncodeMeshToBuffer(*mesh, &out);
  EXPECT_TRUE(status.ok()) << status.error_msg_string();
  return {out.data(), out.data() + out.size()};
}

// The grid as KHR_draco_mesh_compression: accessors with type and count but no data, the Draco stream in a view.
std::filesystem::path write_draco(const Grid& g, const std::vector<unsigned char>& stream, int position_id,
                                  int normal_id, const std::string& name) {
  GltfBuilder b;
  b.bin = stream;
  b.doc["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 0}, {"byteLength", stream.size()}});
  const size_t n = g.positions.size() / 3;
  b.doc["accessors"] = {
      {{"componentType", 5126}, {"count", n}, {"type", "VEC3"}, {"min", {-0.5, -0.5, -0.3}}, {"max", {0.5, 0.5, 0.3}}},
      {{"componentType", 5126}, {"count", n}, {"type", "VEC3"}},
      {{"componentType", 5123}, {"count", g.indices.size()}, {"type", "SCALAR"}}};
  b.doc["meshes"].push_back(
      {{"primitives",
        {{{"attributes", {{"POSITION", 0}, {"NORMAL", 1}}},
          {"indices", 2},
          {"extensions",
           {{"KHR_draco_mesh_compression",
             {{"bufferView", 0}, {"attributes", {{"POSITION", position_id}, {"NORMAL", normal_id}}}}}}}}}}});
  b.node({{"mesh", 0}}, true);
  b.doc["extensionsUsed"] = {"KHR_draco_mesh_compression"};
  b.doc["extensionsRequired"] = {"KHR_draco_mesh_compression"};
  return b.write(fixture_dir(), name);
}

TEST(GltfCompression, DracoMeshEqualsItsUncompressedTwin) {
  const Grid g = grid(5);
  const std::vector<Triangle> plain = import_triangles(write_plain(g, "plain"));
  ASSERT_EQ(plain.size(), 32u);
  for (int method : {draco::MESH_SEQUENTIAL_ENCODING, draco::MESH_EDGEBREAKER_ENCODING}) {
    int position_id, normal_id;
    const std::vector<unsigned char> stream = draco_bytes(g, &position_id, &normal_id, method);
    const std::vector<Triangle> decoded =
        import_triangles(write_draco(g, stream, position_id, normal_id, "draco" + std::to_string(method)));
    EXPECT_EQ(decoded, plain) << "Draco encoding method " << method;
  }
}

TEST(GltfCompression, MalformedDracoStreamsAreRefused) {
  const Grid g = grid(4);
  int position_id, normal_id;
  std::vector<unsigned char> stream = draco_bytes(g, &position_id, &normal_id, draco::MESH_EDGEBREAKER_ENCODING);
  // Cut short, and with its body overwritten: a SceneError naming the extension, never a crash.
  for (int variant = 0; variant < 2; ++variant) {
    std::vector<unsigned char> bad = stream;
    if (variant == 0)
      bad.resize(bad.size() / 2);
    else
      for (size_t i = 12; i < bad.size(); ++i) bad[i] = static_cast<unsigned char>(i * 37);
    Scene scene;
    try {
      import_gltf(write_draco(g, bad, position_id, normal_id, "bad_draco"), "/scene/gltf", scene, {});
      ADD_FAILURE() << "variant " << variant << " was accepted";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("KHR_draco_mesh_compression"), std::string::npos) << e.what();
    }
  }
  // An attribute id the stream does not have.
  Scene scene;
  EXPECT_THROW(import_gltf(write_draco(g, stream, 7, normal_id, "bad_draco_id"), "/scene/gltf", scene, {}), SceneError);
}

// The grid as EXT_meshopt_compression: buffer 0 holds the compressed streams, buffer 1 is the fallback (no URI, as
// the specification allows when the extension is required), which every compressed view names as its own buffer.
std::filesystem::path write_meshopt(const Grid& g, const std::string& name, bool view_without_extension = false) {
  GltfBuilder b;
  b.doc["buffers"] = json::array();
  std::vector<unsigned char>& bin = b.bin;
  const size_t n = g.positions.size() / 3;
  size_t fallback_size = 0;
  auto add = [&](const std::vector<unsigned char>& encoded, size_t count, size_t stride, const char* mode) {
    while (bin.size() % 4) bin.push_back(0);
    const size_t offset = bin.size();
    bin.insert(bin.end(), encoded.begin(), encoded.end());
    json view = {{"buffer", 1},
                 {"byteOffset", fallback_size},
                 {"byteLength", count * stride},
                 {"extensions",
                  {{"EXT_meshopt_compression",
                    {{"buffer", 0},
                     {"byteOffset", offset},
                     {"byteLength", encoded.size()},
                     {"byteStride", stride},
                     {"count", count},
                     {"mode", mode}}}}}};
    if (std::string(mode) == "ATTRIBUTES") view["byteStride"] = stride;
    fallback_size += count * stride;
    b.doc["bufferViews"].push_back(view);
    return static_cast<int>(b.doc["bufferViews"].size()) - 1;
  };
  auto vertices = [&](const std::vector<float>& v) {
    std::vector<unsigned char> out(meshopt_encodeVertexBufferBound(n, 12));
    out.resize(meshopt_encodeVertexBuffer(out.data(), out.size(), v.data(), n, 12));
    return add(out, n, 12, "ATTRIBUTES");
  };
  const int pv = vertices(g.positions), nv = vertices(g.normals);
  std::vector<unsigned int> idx(g.indices.begin(), g.indices.end());
  std::vector<unsigned char> encoded(meshopt_encodeIndexBufferBound(idx.size(), n));
  encoded.resize(meshopt_encodeIndexBuffer(encoded.data(), encoded.size(), idx.data(), idx.size()));
  const int iv = add(encoded, idx.size(), 2, "TRIANGLES");
  if (view_without_extension) b.doc["bufferViews"][iv].erase("extensions");
  b.doc["accessors"] = {{{"bufferView", pv},
                         {"componentType", 5126},
                         {"count", n},
                         {"type", "VEC3"},
                         {"min", {-0.5, -0.5, -0.3}},
                         {"max", {0.5, 0.5, 0.3}}},
                        {{"bufferView", nv}, {"componentType", 5126}, {"count", n}, {"type", "VEC3"}},
                        {{"bufferView", iv}, {"componentType", 5123}, {"count", idx.size()}, {"type", "SCALAR"}}};
  b.doc["meshes"].push_back({{"primitives", {{{"attributes", {{"POSITION", 0}, {"NORMAL", 1}}}, {"indices", 2}}}}});
  b.node({{"mesh", 0}}, true);
  b.doc["extensionsUsed"] = {"EXT_meshopt_compression"};
  b.doc["extensionsRequired"] = {"EXT_meshopt_compression"};
  // Written by hand: the builder's one buffer would be the compressed one; the fallback follows it.
  while (bin.size() % 4) bin.push_back(0);
  b.doc["buffers"] = {
      {{"byteLength", bin.size()}, {"uri", "data:application/octet-stream;base64," + test::base64(bin)}},
      {{"byteLength", fallback_size}, {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}}};
  b.doc.erase("materials");
  const auto path = fixture_dir() / (name + ".gltf");
  std::ofstream(path) << b.doc.dump(1);
  return path;
}

TEST(GltfCompression, MeshoptMeshEqualsItsUncompressedTwinAndItsFallbackIsNotRead) {
  const Grid g = grid(5);
  const std::vector<Triangle> plain = import_triangles(write_plain(g, "plain_m"));
  ASSERT_EQ(plain.size(), 32u);
  // The fallback buffer has no URI and no data: read, it would fail or give zeros.
  EXPECT_EQ(import_triangles(write_meshopt(g, "meshopt")), plain);
}

TEST(GltfCompression, MeshoptFallbackBuffersAreReadOnlyThroughTheExtension) {
  const Grid g = grid(4);
  Scene scene;
  try {
    import_gltf(write_meshopt(g, "meshopt_fallback_read", true), "/scene/gltf", scene, {});
    ADD_FAILURE() << "a view reading the fallback buffer directly was accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("fallback"), std::string::npos) << e.what();
  }
}

TEST(GltfCompression, MalformedMeshoptStreamsAreRefused) {
  const Grid g = grid(4);
  const auto path = write_meshopt(g, "meshopt_bad");
  json doc = json::parse(std::ifstream(path));
  // Every case a SceneError: a stride the decoder cannot take, an unknown mode, a count beyond the data, a filter
  // whose stride does not fit.
  const std::vector<std::pair<std::string, json>> cases = {
      {"/bufferViews/0/extensions/EXT_meshopt_compression/byteStride", 6},
      {"/bufferViews/0/extensions/EXT_meshopt_compression/mode", "SOMETHING"},
      {"/bufferViews/2/extensions/EXT_meshopt_compression/count", 3000},
      {"/bufferViews/2/extensions/EXT_meshopt_compression/count", 31},
      {"/bufferViews/0/extensions/EXT_meshopt_compression/filter", "QUATERNION"},
  };
  for (const auto& [where, value] : cases) {
    json bad = doc;
    bad[json::json_pointer(where)] = value;
    const auto bad_path = fixture_dir() / "meshopt_bad_case.gltf";
    std::ofstream(bad_path) << bad.dump();
    Scene scene;
    try {
      import_gltf(bad_path, "/scene/gltf", scene, {});
      ADD_FAILURE() << where << " = " << value << " was accepted";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("EXT_meshopt_compression"), std::string::npos) << e.what();
    }
  }
}

// Renders `file` of the fixture folder as a job would: the path tracer, 16x16, 2 samples per pixel.
void render_small(const std::filesystem::path& file) {
  JobLoadOptions options;
  options.scene.asset_root = fixture_dir();
  RenderJob job = load_job(
      json{{"scene", {{"gltf", file.filename().string()}}}, {"render", {{"width", 16}, {"height", 16}, {"spp", 2}}}},
      options);
  ThreadPool pool(2);
  RenderSession session(job.scene, job.settings, pool);
  session.run();
}

// A fuzzer's mutations of a valid Draco stream (1 to 16 bytes changed at random places) that Draco still decodes
// can hold any coordinates: each is refused when it loads, or loads as geometry that renders. Before geometry was
// checked, some made rays Embree aborts on (its RayK::valid assertion), and the process died.
TEST(GltfCompression, MutatedDracoStreamsAreRefusedOrRender) {
  const Grid g = grid(6);
  int position_id, normal_id;
  const std::vector<unsigned char> stream = draco_bytes(g, &position_id, &normal_id, draco::MESH_SEQUENTIAL_ENCODING);
  std::mt19937 random(20261127);
  int refused = 0, rendered = 0;
  for (int trial = 0; trial < 150; ++trial) {
    std::vector<unsigned char> mutated = stream;
    const int changes = 1 + static_cast<int>(random() % 16);
    for (int k = 0; k < changes; ++k) mutated[random() % mutated.size()] = static_cast<unsigned char>(random());
    const auto file = write_draco(g, mutated, position_id, normal_id, "mutated");
    try {
      render_small(file);
      ++rendered;
    } catch (const SceneError&) {
      ++refused;
    }
  }
  EXPECT_GT(refused, 0);
  EXPECT_GT(rendered, 0);
}

// meshopt's decoder writes the whole declared output before it can tell the data is bad: a view declaring 8e6
// vertices of 256 bytes over a few bytes of data is refused for what it would make, before it is made.
TEST(GltfCompression, AMeshoptViewCannotDeclareMoreThanItsBytesAllow) {
  const Grid g = grid(4);
  const auto file = write_meshopt(g, "meshopt_huge");
  json doc = json::parse(std::ifstream(file));
  for (json& view : doc["bufferViews"]) {
    json& ext = view["extensions"]["EXT_meshopt_compression"];
    if (ext["mode"] != "ATTRIBUTES") continue;
    ext["count"] = 8'000'000;
    ext["byteStride"] = 256;
    view["byteLength"] = 8'000'000ull * 256;
  }
  std::ofstream(file) << doc.dump();
  Scene scene;
  try {
    import_gltf(file, "/scene/gltf", scene, {});
    ADD_FAILURE() << "accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("EXT_meshopt_compression would make the asset's decoded geometry larger than"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace tessera
