// glTF meshes: accessors read with every offset checked, primitives triangulated, morph targets applied at the pose's
// or the mesh's default weights, skinned vertices posed by their joints.
#include <algorithm>
#include <cstring>

#include "renderer/gltf/internal.h"

namespace tessera::gltf {

namespace {

// One component as a float: normalised integers mapped to [0,1] / [-1,1], non-finite floats to 0.
float to_float(const tinygltf::Accessor& acc, const unsigned char* p) {
  switch (acc.componentType) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
      float f;
      std::memcpy(&f, p, 4);
      return std::isfinite(f) ? f : 0.0f;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return acc.normalized ? *p / 255.0f : *p;
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      int8_t b;
      std::memcpy(&b, p, 1);
      return acc.normalized ? std::max(b / 127.0f, -1.0f) : b;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
      uint16_t s;
      std::memcpy(&s, p, 2);
      return acc.normalized ? s / 65535.0f : s;
    }
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      int16_t s;
      std::memcpy(&s, p, 2);
      return acc.normalized ? std::max(s / 32767.0f, -1.0f) : s;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
      uint32_t u;
      std::memcpy(&u, p, 4);
      return static_cast<float>(u);
    }
    default:
      return 0.0f;
  }
}

}  // namespace

// Where an accessor's bytes are, every range checked against the bytes that exist (before anything is allocated).
struct AccessorReader::Layout {
  int comps = 0, csize = 0;
  size_t elem = 0;
  const unsigned char* base = nullptr;  // the first element; null: zeros (no buffer view)
  size_t stride = 0;
  const unsigned char* sparse_indices = nullptr;  // sparse.count indices of sparse_index_size bytes
  const unsigned char* sparse_values = nullptr;   // sparse.count elements
  int sparse_index_size = 0;
};

AccessorReader::Layout AccessorReader::layout(const tinygltf::Accessor& acc, int index) const {
  Layout at;
  at.comps = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(acc.type));
  at.csize = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(acc.componentType));
  if (at.comps <= 0 || at.csize <= 0) fail(index, "has an unknown type or component type");
  at.elem = static_cast<size_t>(at.comps) * static_cast<size_t>(at.csize);
  if (acc.bufferView >= 0) {
    size_t available;
    view(acc.bufferView, index, &at.base, &available, &at.stride);
    if (at.stride == 0) at.stride = at.elem;
    if (at.stride < at.elem) fail(index, "has a byte stride smaller than its element");
    if (acc.count > 0 &&
        (acc.byteOffset > available || (acc.count - 1) * at.stride + at.elem > available - acc.byteOffset))
      fail(index, "reads beyond the end of its buffer view");
    at.base += acc.byteOffset;
  } else {
    // glTF 2.0, 5.1 (accessor.bufferView): without a buffer view the accessor is zeros, which the import makes.
    budget_.take(acc.count * at.elem, "accessor " + std::to_string(index));
  }
  if (acc.sparse.isSparse) {
    const auto& sp = acc.sparse;
    if (sp.count < 0 || static_cast<size_t>(sp.count) > acc.count) fail(index, "has a bad sparse count");
    size_t iavail, vavail, istride, vstride;
    view(sp.indices.bufferView, index, &at.sparse_indices, &iavail, &istride);
    view(sp.values.bufferView, index, &at.sparse_values, &vavail, &vstride);
    at.sparse_index_size = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(sp.indices.componentType));
    if (at.sparse_index_size <= 0 ||
        static_cast<size_t>(sp.indices.byteOffset) + static_cast<size_t>(sp.count) * at.sparse_index_size > iavail ||
        static_cast<size_t>(sp.values.byteOffset) + static_cast<size_t>(sp.count) * at.elem > vavail)
      fail(index, "has sparse data beyond its buffer views");
    at.sparse_indices += sp.indices.byteOffset;
    at.sparse_values += sp.values.byteOffset;
  }
  return at;
}

std::vector<float> AccessorReader::floats(int index, int components) const {
  const tinygltf::Accessor& acc = accessor(index);
  int have = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(acc.type));
  if (have != components)
    fail(index, "has " + std::to_string(have) + " components where " + std::to_string(components) + " are needed");
  const Layout at = layout(acc, index);
  std::vector<float> out(acc.count * components, 0.0f);
  read(acc, index, at, [&](size_t i, int c, const unsigned char* p) { out[i * components + c] = to_float(acc, p); });
  return out;
}

std::vector<uint32_t> AccessorReader::indices(int index, size_t vertex_count) const {
  const tinygltf::Accessor& acc = accessor(index);
  if (acc.type != TINYGLTF_TYPE_SCALAR) fail(index, "indices must be scalars");
  const Layout at = layout(acc, index);
  std::vector<uint32_t> out(acc.count);
  read(acc, index, at, [&](size_t i, int, const unsigned char* p) {
    uint32_t v;
    switch (acc.componentType) {
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        v = *p;
        break;
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t s;
        std::memcpy(&s, p, 2);
        v = s;
        break;
      }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
        std::memcpy(&v, p, 4);
        break;
      default:
        fail(index, "indices must be unsigned integers");
    }
    if (v >= vertex_count)
      fail(index, "index " + std::to_string(v) + " is beyond the " + std::to_string(vertex_count) + " vertices");
    out[i] = v;
  });
  return out;
}

size_t AccessorReader::count(int index) const {
  return accessor(index).count;
}

void AccessorReader::fail(int index, const std::string& what) const {
  throw SceneError(pointer_, "accessor " + std::to_string(index) + " " + what);
}

const tinygltf::Accessor& AccessorReader::accessor(int index) const {
  if (index < 0 || index >= static_cast<int>(model_.accessors.size())) fail(index, "does not exist");
  const tinygltf::Accessor& acc = model_.accessors[index];
  if (acc.count > (size_t{1} << 28)) fail(index, "has an implausible count");
  return acc;
}

// Calls fn(element, component, bytes) for every component of an accessor laid out `at`: dense data (or zeros)
// first, then sparse substitutions.
template <typename Fn>
void AccessorReader::read(const tinygltf::Accessor& acc, int index, const Layout& at, Fn&& fn) const {
  const std::vector<unsigned char> zero(at.base ? 0 : at.elem, 0);
  for (size_t i = 0; i < acc.count; ++i) {
    const unsigned char* element = at.base ? at.base + i * at.stride : zero.data();
    for (int c = 0; c < at.comps; ++c) fn(i, c, element + static_cast<size_t>(c) * at.csize);
  }
  if (!acc.sparse.isSparse) return;
  for (int k = 0; k < acc.sparse.count; ++k) {
    const unsigned char* ip = at.sparse_indices + static_cast<size_t>(k) * at.sparse_index_size;
    uint32_t target = 0;
    if (at.sparse_index_size == 1) {
      target = *ip;
    } else if (at.sparse_index_size == 2) {
      uint16_t s;
      std::memcpy(&s, ip, 2);
      target = s;
    } else {
      std::memcpy(&target, ip, 4);
    }
    if (target >= acc.count) fail(index, "has a sparse index beyond its count");
    for (int c = 0; c < at.comps; ++c)
      fn(target, c, at.sparse_values + static_cast<size_t>(k) * at.elem + static_cast<size_t>(c) * at.csize);
  }
}

void AccessorReader::view(int view_index, int accessor_index, const unsigned char** base, size_t* length,
                          size_t* stride) const {
  if (view_index < 0 || view_index >= static_cast<int>(model_.bufferViews.size()))
    fail(accessor_index, "names a buffer view that does not exist");
  const tinygltf::BufferView& v = model_.bufferViews[view_index];
  if (v.buffer < 0 || v.buffer >= static_cast<int>(model_.buffers.size()))
    fail(accessor_index, "uses a buffer view whose buffer does not exist");
  const tinygltf::Buffer& b = model_.buffers[v.buffer];
  if (v.byteOffset > b.data.size() || v.byteLength > b.data.size() - v.byteOffset)
    throw SceneError(pointer_, "buffer view " + std::to_string(view_index) + " declares " +
                                   std::to_string(v.byteOffset + v.byteLength) + " bytes but buffer " +
                                   std::to_string(v.buffer) + " has " + std::to_string(b.data.size()));
  *base = b.data.data() + v.byteOffset;
  *length = v.byteLength;
  *stride = v.byteStride;
}

std::vector<Mesh> build_meshes(Import& import, const AccessorReader& reader, Materials& materials, int mesh_index,
                               const TransformD& world, const std::vector<TransformD>* joints,
                               const std::vector<double>* pose_weights) {
  const tinygltf::Model& model = import.model;
  const std::string& pointer = import.pointer;
  const bool flip = world.determinant() < 0;  // a mirroring transform reverses the winding
  const TransformD nmat = world.normal_transform();
  std::vector<Mesh> out;
  for (const tinygltf::Primitive& prim : model.meshes[mesh_index].primitives) {
    import.check_stop();
    if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
        prim.mode != TINYGLTF_MODE_TRIANGLE_FAN) {
      import.warn("mesh " + std::to_string(mesh_index) + ": points and lines are not rendered");
      continue;
    }
    auto pos_it = prim.attributes.find("POSITION");
    if (pos_it == prim.attributes.end()) continue;
    Mesh mesh;
    import.count_vertices(reader.count(pos_it->second));
    std::vector<float> pos = reader.floats(pos_it->second, 3);
    const size_t nv = pos.size() / 3;
    // Morph targets at the pose's weights, else the mesh's default weights (glTF 2.0, 3.7.2.2): attribute + sum of
    // weight_k * target_k's displacement, for POSITION, NORMAL and TANGENT (whose targets are 3-vectors added to xyz).
    const std::vector<double>& weights =
        pose_weights && !pose_weights->empty() ? *pose_weights : model.meshes[mesh_index].weights;
    auto morph = [&](std::vector<float>& values, const char* name, int stride) {
      for (size_t k = 0; k < prim.targets.size() && k < weights.size(); ++k) {
        auto it = prim.targets[k].find(name);
        if (it == prim.targets[k].end() || weights[k] == 0) continue;
        if (reader.count(it->second) != nv)
          throw SceneError(pointer, "mesh " + std::to_string(mesh_index) + ": morph target " + std::to_string(k) + " " +
                                        name + " has another count than POSITION");
        const std::vector<float> d = reader.floats(it->second, 3);
        const float w = static_cast<float>(weights[k]);
        for (size_t v = 0; v < nv; ++v)
          for (int c = 0; c < 3; ++c) values[v * stride + c] += w * d[3 * v + c];
      }
    };
    morph(pos, "POSITION", 3);
    std::vector<TransformD> skin_at;  // per vertex, when skinned
    if (joints) {
      auto ji = prim.attributes.find("JOINTS_0"), wi = prim.attributes.find("WEIGHTS_0");
      if (ji == prim.attributes.end() || wi == prim.attributes.end() || reader.count(ji->second) != nv ||
          reader.count(wi->second) != nv)
        throw SceneError(pointer, "mesh " + std::to_string(mesh_index) +
                                      ": a skinned mesh needs JOINTS_0 and WEIGHTS_0 for every vertex");
      const std::vector<float> jv = reader.floats(ji->second, 4), wv = reader.floats(wi->second, 4);
      skin_at.resize(nv);
      for (size_t v = 0; v < nv; ++v) {
        TransformD m;
        for (auto& row : m.m) std::fill(std::begin(row), std::end(row), 0.0);
        for (int k = 0; k < 4; ++k) {
          const float w = wv[4 * v + k];
          if (w == 0) continue;
          const size_t j = static_cast<size_t>(jv[4 * v + k]);
          if (j >= joints->size())
            throw SceneError(pointer, "mesh " + std::to_string(mesh_index) + ": JOINTS_0 names joint " +
                                          std::to_string(j) + " of a skin of " + std::to_string(joints->size()));
          for (int row = 0; row < 3; ++row)
            for (int col = 0; col < 4; ++col) m.m[row][col] += w * (*joints)[j].m[row][col];
        }
        skin_at[v] = m;
      }
    }
    auto vertex_world = [&](size_t v) -> const TransformD& { return skin_at.empty() ? world : skin_at[v]; };
    mesh.positions.resize(nv);
    for (size_t v = 0; v < nv; ++v) {
      mesh.positions[v] = vertex_world(v).point(Vec3(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]));
    }
    auto attr = [&](const char* name) {
      auto it = prim.attributes.find(name);
      return it == prim.attributes.end() ? -1 : it->second;
    };
    auto check_count = [&](int acc, const char* name) {
      if (reader.count(acc) != nv)
        throw SceneError(pointer, std::string("mesh ") + std::to_string(mesh_index) + ": " + name + " has " +
                                      std::to_string(reader.count(acc)) + " elements for " + std::to_string(nv) +
                                      " positions");
    };
    if (int a = attr("NORMAL"); a >= 0) {
      check_count(a, "NORMAL");
      std::vector<float> n = reader.floats(a, 3);
      morph(n, "NORMAL", 3);
      mesh.normals.resize(nv);
      for (size_t v = 0; v < nv; ++v) {
        Vec3 wn =
            (skin_at.empty() ? nmat : skin_at[v].normal_transform()).vector(Vec3(n[3 * v], n[3 * v + 1], n[3 * v + 2]));
        float len = length(wn);
        mesh.normals[v] = len > 0 && std::isfinite(len) ? wn / len : Vec3(0, 0, 1);
      }
    }
    if (int a = attr("TANGENT"); a >= 0 && !mesh.normals.empty()) {
      check_count(a, "TANGENT");
      std::vector<float> t = reader.floats(a, 4);
      morph(t, "TANGENT", 4);
      mesh.tangents.resize(nv);
      mesh.tangent_signs.resize(nv);
      for (size_t v = 0; v < nv; ++v) {
        Vec3 wt = vertex_world(v).vector(Vec3(t[4 * v], t[4 * v + 1], t[4 * v + 2]));
        float len = length(wt);
        mesh.tangents[v] = len > 0 && std::isfinite(len) ? wt / len : Vec3(1, 0, 0);
        mesh.tangent_signs[v] = (t[4 * v + 3] < 0 ? -1.0f : 1.0f) * (flip ? -1.0f : 1.0f);
      }
    }
    for (int set = 0; set < 2; ++set) {
      int a = attr(set == 0 ? "TEXCOORD_0" : "TEXCOORD_1");
      if (a < 0) continue;
      check_count(a, set == 0 ? "TEXCOORD_0" : "TEXCOORD_1");
      std::vector<float> uv = reader.floats(a, 2);
      auto& dst = set == 0 ? mesh.uvs : mesh.uvs1;
      dst.resize(nv);
      for (size_t v = 0; v < nv; ++v) dst[v] = Vec2(uv[2 * v], uv[2 * v + 1]);  // glTF: origin top-left
    }
    if (int a = attr("COLOR_0"); a >= 0) {
      check_count(a, "COLOR_0");
      int comps = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(model.accessors[a].type));
      std::vector<float> c = reader.floats(a, comps == 4 ? 4 : 3);
      mesh.colors.resize(nv);
      for (size_t v = 0; v < nv; ++v) mesh.colors[v] = Rgb(c[comps * v], c[comps * v + 1], c[comps * v + 2]);
    }
    std::vector<uint32_t> idx;
    if (prim.indices >= 0) {
      idx = reader.indices(prim.indices, nv);
    } else {
      idx.resize(nv);
      for (size_t v = 0; v < nv; ++v) idx[v] = static_cast<uint32_t>(v);
    }
    // Triangulate strips and fans (spec 3.7.2.1).
    std::vector<uint32_t> tri;
    if (prim.mode == TINYGLTF_MODE_TRIANGLES) {
      tri.assign(idx.begin(), idx.begin() + static_cast<std::ptrdiff_t>(idx.size() / 3 * 3));
    } else if (prim.mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
      for (size_t i = 0; i + 2 < idx.size(); ++i) {
        if (i % 2 == 0)
          tri.insert(tri.end(), {idx[i], idx[i + 1], idx[i + 2]});
        else
          tri.insert(tri.end(), {idx[i + 1], idx[i], idx[i + 2]});
      }
    } else {
      for (size_t i = 1; i + 1 < idx.size(); ++i) tri.insert(tri.end(), {idx[0], idx[i], idx[i + 1]});
    }
    if (flip)
      for (size_t i = 0; i + 2 < tri.size(); i += 3) std::swap(tri[i + 1], tri[i + 2]);
    import.triangles += tri.size() / 3;
    import.check_triangles();
    mesh.indices = std::move(tri);
    if (prim.material >= static_cast<int>(model.materials.size()))
      throw SceneError(pointer,
                       "a primitive names material " + std::to_string(prim.material) + ", which does not exist");
    mesh.material = prim.material >= 0 ? materials.index[prim.material] : materials.default_material(import);
    if (!mesh.indices.empty()) out.push_back(std::move(mesh));
  }
  return out;
}

}  // namespace tessera::gltf
