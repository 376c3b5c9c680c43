// Writes small glTF 2.0 fixtures for tests: geometry in one buffer, embedded as a data: URI or beside the file.
#pragma once

#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace tessera::test {

// Where a test process writes its glTF fixtures: one folder per process, removed when the process ends;
// TESSERA_GLTF_FIXTURES keeps them in a given folder (for the Khronos validator test, tests/gltf/CMakeLists.txt).
inline std::filesystem::path gltf_fixture_dir() {
  static const struct Folder {
    const char* keep = std::getenv("TESSERA_GLTF_FIXTURES");
    std::filesystem::path path =
        keep ? std::filesystem::path(keep)
             : std::filesystem::temp_directory_path() / ("tessera-gltf-" + std::to_string(::getpid()));
    Folder() { std::filesystem::create_directories(path); }
    ~Folder() {
      std::error_code ec;
      if (!keep) std::filesystem::remove_all(path, ec);
    }
  } folder;
  return folder.path;
}

inline std::string base64(const std::vector<unsigned char>& in) {
  static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    unsigned v = (in[i] << 16) | (in[i + 1] << 8) | in[i + 2];
    out += {t[v >> 18], t[(v >> 12) & 63], t[(v >> 6) & 63], t[v & 63]};
  }
  if (i + 1 == in.size()) {
    unsigned v = in[i] << 16;
    out += {t[v >> 18], t[(v >> 12) & 63], '=', '='};
  } else if (i + 2 == in.size()) {
    unsigned v = (in[i] << 16) | (in[i + 1] << 8);
    out += {t[v >> 18], t[(v >> 12) & 63], t[(v >> 6) & 63], '='};
  }
  return out;
}

// Accumulates a glTF document and its single binary buffer.
class GltfBuilder {
 public:
  nlohmann::json doc = {{"asset", {{"version", "2.0"}, {"generator", "tessera tests"}}},
                        {"scenes", nlohmann::json::array({{{"nodes", nlohmann::json::array()}}})},
                        {"scene", 0},
                        {"nodes", nlohmann::json::array()},
                        {"meshes", nlohmann::json::array()},
                        {"accessors", nlohmann::json::array()},
                        {"bufferViews", nlohmann::json::array()},
                        {"materials", nlohmann::json::array()}};
  std::vector<unsigned char> bin;

  // Appends float data as an accessor of `type` ("VEC3", "VEC2", "SCALAR"); returns its index.
  int floats(const std::vector<float>& v, const std::string& type, int components) {
    nlohmann::json acc = {{"bufferView", view(v.data(), v.size() * 4)},
                          {"componentType", 5126},
                          {"count", v.size() / components},
                          {"type", type}};
    if (type == "VEC3") {
      float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
      for (size_t i = 0; i < v.size(); ++i) {
        lo[i % 3] = std::min(lo[i % 3], v[i]);
        hi[i % 3] = std::max(hi[i % 3], v[i]);
      }
      acc["min"] = {lo[0], lo[1], lo[2]};
      acc["max"] = {hi[0], hi[1], hi[2]};
    }
    doc["accessors"].push_back(acc);
    return static_cast<int>(doc["accessors"].size()) - 1;
  }
  int indices16(const std::vector<uint16_t>& v) {
    doc["accessors"].push_back({{"bufferView", view(v.data(), v.size() * 2)},
                                {"componentType", 5123},
                                {"count", v.size()},
                                {"type", "SCALAR"}});
    return static_cast<int>(doc["accessors"].size()) - 1;
  }
  int material(const nlohmann::json& m) {
    doc["materials"].push_back(m);
    return static_cast<int>(doc["materials"].size()) - 1;
  }
  // A mesh of one triangle-list primitive; returns the mesh index.
  int mesh(const std::vector<float>& positions, const std::vector<uint16_t>& idx, int material,
           const std::vector<float>& normals = {}) {
    nlohmann::json attrs = {{"POSITION", floats(positions, "VEC3", 3)}};
    if (!normals.empty()) attrs["NORMAL"] = floats(normals, "VEC3", 3);
    nlohmann::json prim = {{"attributes", attrs}, {"indices", indices16(idx)}};
    if (material >= 0) prim["material"] = material;
    doc["meshes"].push_back({{"primitives", nlohmann::json::array({prim})}});
    return static_cast<int>(doc["meshes"].size()) - 1;
  }
  // Embeds PNG bytes as a data: URI image with a texture on it; returns the texture index.
  int texture_png(const std::vector<unsigned char>& png, const nlohmann::json& sampler = nullptr) {
    if (!doc.contains("images")) doc["images"] = nlohmann::json::array();
    if (!doc.contains("textures")) doc["textures"] = nlohmann::json::array();
    doc["images"].push_back({{"uri", "data:image/png;base64," + base64(png)}});
    nlohmann::json tex = {{"source", doc["images"].size() - 1}};
    if (!sampler.is_null()) {
      if (!doc.contains("samplers")) doc["samplers"] = nlohmann::json::array();
      doc["samplers"].push_back(sampler);
      tex["sampler"] = doc["samplers"].size() - 1;
    }
    doc["textures"].push_back(tex);
    return static_cast<int>(doc["textures"].size()) - 1;
  }
  // A mesh with texture coordinates (and optional normals).
  int textured_mesh(const std::vector<float>& positions, const std::vector<float>& uvs,
                    const std::vector<uint16_t>& idx, int material) {
    nlohmann::json attrs = {{"POSITION", floats(positions, "VEC3", 3)}, {"TEXCOORD_0", floats(uvs, "VEC2", 2)}};
    nlohmann::json prim = {{"attributes", attrs}, {"indices", indices16(idx)}, {"material", material}};
    doc["meshes"].push_back({{"primitives", nlohmann::json::array({prim})}});
    return static_cast<int>(doc["meshes"].size()) - 1;
  }
  int node(const nlohmann::json& n, bool root) {
    doc["nodes"].push_back(n);
    int i = static_cast<int>(doc["nodes"].size()) - 1;
    if (root) doc["scenes"][0]["nodes"].push_back(i);
    return i;
  }
  // Writes `dir/name.gltf` with the buffer embedded as a data: URI; returns the path.
  std::filesystem::path write(const std::filesystem::path& dir, const std::string& name) {
    finish_buffer("data:application/octet-stream;base64," + base64(bin));
    std::filesystem::create_directories(dir);
    auto path = dir / (name + ".gltf");
    std::ofstream(path) << doc.dump(1);
    return path;
  }
  // Writes `dir/name.glb`.
  std::filesystem::path write_glb(const std::filesystem::path& dir, const std::string& name) {
    finish_buffer("");
    std::string j = doc.dump();
    while (j.size() % 4) j += ' ';
    std::vector<unsigned char> b = bin;
    while (b.size() % 4) b.push_back(0);
    std::vector<unsigned char> out;
    auto u32 = [&](uint32_t v) {
      for (int i = 0; i < 4; ++i) out.push_back(static_cast<unsigned char>(v >> (8 * i)));
    };
    out.insert(out.end(), {'g', 'l', 'T', 'F'});
    u32(2);
    u32(static_cast<uint32_t>(12 + 8 + j.size() + (b.empty() ? 0 : 8 + b.size())));
    u32(static_cast<uint32_t>(j.size()));
    u32(0x4E4F534A);
    out.insert(out.end(), j.begin(), j.end());
    if (!b.empty()) {  // no buffer, no BIN chunk
      u32(static_cast<uint32_t>(b.size()));
      u32(0x004E4942);
      out.insert(out.end(), b.begin(), b.end());
    }
    std::filesystem::create_directories(dir);
    auto path = dir / (name + ".glb");
    std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(out.data()), out.size());
    return path;
  }

 private:
  int view(const void* data, size_t bytes) {
    while (bin.size() % 4) bin.push_back(0);
    size_t offset = bin.size();
    bin.resize(offset + bytes);
    std::memcpy(bin.data() + offset, data, bytes);
    doc["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}});
    return static_cast<int>(doc["bufferViews"].size()) - 1;
  }
  void finish_buffer(const std::string& uri) {
    nlohmann::json buffer = {{"byteLength", bin.size()}};
    if (!uri.empty()) buffer["uri"] = uri;
    doc["buffers"] = nlohmann::json::array({buffer});
    if (bin.empty()) doc.erase("buffers");  // a buffer has at least one byte
    if (doc["materials"].empty()) doc.erase("materials");
  }
};

// Nodes 0..levels below the scene, node i listing node i + 1 `fan_out` times, the last holding one triangle when
// `with_mesh`. The specification wants the hierarchy to be trees; shared children like these make fan_out^levels
// paths to the last node from a file of a few hundred bytes.
inline GltfBuilder shared_children_chain(int levels, int fan_out, bool with_mesh) {
  GltfBuilder b;
  for (int i = 0; i <= levels; ++i) {
    nlohmann::json node = nlohmann::json::object();
    if (i < levels) node["children"] = std::vector<int>(static_cast<size_t>(fan_out), i + 1);
    if (i == levels && with_mesh) node["mesh"] = b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, -1);
    b.node(node, i == 0);
  }
  return b;
}

}  // namespace tessera::test
