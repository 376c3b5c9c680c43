// Compressed glTF geometry, decoded into plain buffers before meshes are built: KHR_draco_mesh_compression (Draco,
// Debian's libdraco) and EXT_meshopt_compression (meshoptimizer, Debian's libmeshoptimizer). Each decoded stream
// becomes a buffer of its own that the primitive's accessors (Draco) or the compressed buffer view (meshopt) then
// read, so the accessor reader sees uncompressed data and checks it as any other.
#include <draco/compression/decode.h>
#include <meshoptimizer.h>

#include <cstring>

#include "renderer/gltf/internal.h"

namespace tessera::gltf {

namespace {

// The bytes of buffer view `index`, checked to lie within its buffer.
std::string_view view_bytes(const Import& import, int index, const std::string& who) {
  const tinygltf::Model& model = import.model;
  if (index < 0 || index >= static_cast<int>(model.bufferViews.size()))
    import.fail(who + " names buffer view " + std::to_string(index) + ", which does not exist");
  const tinygltf::BufferView& v = model.bufferViews[index];
  if (v.buffer < 0 || v.buffer >= static_cast<int>(model.buffers.size()))
    import.fail(who + ": buffer view " + std::to_string(index) + " names a buffer that does not exist");
  const std::vector<unsigned char>& data = model.buffers[v.buffer].data;
  if (v.byteOffset > data.size() || v.byteLength > data.size() - v.byteOffset)
    import.fail(who + ": buffer view " + std::to_string(index) + " lies beyond the end of buffer " +
                std::to_string(v.buffer));
  return {reinterpret_cast<const char*>(data.data()) + v.byteOffset, v.byteLength};
}

// Appends `bytes` as a new buffer and a buffer view over all of it; returns the view's index.
int add_view(tinygltf::Model& model, std::vector<unsigned char> bytes, size_t stride = 0) {
  tinygltf::Buffer buffer;
  buffer.data = std::move(bytes);
  tinygltf::BufferView view;
  view.buffer = static_cast<int>(model.buffers.size());
  view.byteOffset = 0;
  view.byteLength = buffer.data.size();
  view.byteStride = stride;
  model.buffers.push_back(std::move(buffer));
  model.bufferViews.push_back(view);
  return static_cast<int>(model.bufferViews.size()) - 1;
}

// KHR_draco_mesh_compression (the extension's specification): the primitive's extension names a buffer view holding
// a Draco mesh and, for each glTF attribute, the Draco attribute's unique id; the primitive's accessors keep their
// type and count, and their data is what Draco decodes (indices as the decoded faces, a triangle list).
void decode_draco_primitive(Import& import, int mesh_index, size_t prim_index) {
  tinygltf::Model& model = import.model;
  tinygltf::Primitive& prim = model.meshes[mesh_index].primitives[prim_index];
  const json ext = parse_extensions(prim.extensions_json_string)["KHR_draco_mesh_compression"];
  const std::string who = "mesh " + std::to_string(mesh_index) + " primitive " + std::to_string(prim_index) +
                          ": KHR_draco_mesh_compression";
  if (!ext.is_object() || !ext.contains("bufferView") || !ext["bufferView"].is_number_integer() ||
      !ext.contains("attributes") || !ext["attributes"].is_object())
    import.fail(who + " needs a bufferView and attributes");
  const std::string_view bytes = view_bytes(import, ext["bufferView"].get<int>(), who);
  draco::DecoderBuffer buffer;
  buffer.Init(bytes.data(), bytes.size());
  std::unique_ptr<draco::Mesh> mesh;
  try {
    draco::Decoder decoder;
    auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
    if (!decoded.ok()) import.fail(who + " cannot be decoded: " + decoded.status().error_msg_string());
    mesh = std::move(decoded).value();
  } catch (const std::bad_alloc&) {
    import.fail(who + " cannot be decoded: it claims more memory than there is");
  }
  if (!mesh) import.fail(who + " cannot be decoded");
  const size_t points = mesh->num_points(), faces = mesh->num_faces();
  if (faces > import.options.max_triangles || points > (size_t{1} << 28))
    import.fail(who + " decodes to " + std::to_string(faces) + " triangles and " + std::to_string(points) +
                " vertices, beyond the limits");
  // Indices: the decoded faces, as 32-bit unsigned integers.
  {
    import.decoded.take(faces * 12, who);
    std::vector<unsigned char> data(faces * 12);
    for (size_t f = 0; f < faces; ++f)
      for (int k = 0; k < 3; ++k) {
        const uint32_t index = mesh->face(draco::FaceIndex(static_cast<uint32_t>(f)))[k].value();
        std::memcpy(&data[(3 * f + k) * 4], &index, 4);
      }
    tinygltf::Accessor acc;
    if (prim.indices >= 0 && prim.indices < static_cast<int>(model.accessors.size()))
      acc = model.accessors[prim.indices];
    acc.bufferView = add_view(model, std::move(data));
    acc.byteOffset = 0;
    acc.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    acc.type = TINYGLTF_TYPE_SCALAR;
    acc.normalized = false;
    acc.count = faces * 3;
    acc.sparse = {};
    model.accessors.push_back(acc);
    prim.indices = static_cast<int>(model.accessors.size()) - 1;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
  }
  // Attributes: each as floats (normalised integers mapped to [0,1] / [-1,1] by Draco), with the accessor's components.
  for (auto& [name, accessor_index] : prim.attributes) {
    if (!ext["attributes"].contains(name)) continue;  // not compressed: read from its own accessor as it is
    const json& id = ext["attributes"][name];
    const draco::PointAttribute* attribute =
        id.is_number_unsigned() ? mesh->GetAttributeByUniqueId(id.get<uint32_t>()) : nullptr;
    if (!attribute) import.fail(who + ": attribute " + name + " names no attribute of the Draco mesh");
    if (accessor_index < 0 || accessor_index >= static_cast<int>(model.accessors.size()))
      import.fail(who + ": attribute " + name + " names an accessor that does not exist");
    tinygltf::Accessor acc = model.accessors[accessor_index];
    const int components = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(acc.type));
    if (components <= 0 || components > 16) import.fail(who + ": attribute " + name + " has an unknown type");
    import.decoded.take(points * components * 4, who);
    std::vector<unsigned char> data(points * components * 4);
    std::vector<float> value(components);
    for (size_t p = 0; p < points; ++p) {
      std::fill(value.begin(), value.end(), 0.0f);
      attribute->ConvertValue<float>(attribute->mapped_index(draco::PointIndex(static_cast<uint32_t>(p))),
                                     static_cast<int8_t>(components), value.data());
      std::memcpy(&data[p * components * 4], value.data(), components * 4);
    }
    acc.bufferView = add_view(model, std::move(data));
    acc.byteOffset = 0;
    acc.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
    acc.normalized = false;
    acc.count = points;
    acc.sparse = {};
    model.accessors.push_back(acc);
    accessor_index = static_cast<int>(model.accessors.size()) - 1;
  }
}

// EXT_meshopt_compression (the extension's specification): a buffer view whose extension names the compressed bytes
// (buffer, byteOffset, byteLength) and how they decode (count elements of byteStride bytes, mode ATTRIBUTES,
// TRIANGLES or INDICES, filter NONE, OCTAHEDRAL, QUATERNION or EXPONENTIAL). Its own buffer is the fallback, which
// is not read. The decoder's preconditions are checked here (the library asserts them).
void decode_meshopt_view(Import& import, int view_index) {
  tinygltf::Model& model = import.model;
  tinygltf::BufferView& view = model.bufferViews[view_index];
  const json ext = parse_extensions(view.extensions_json_string)["EXT_meshopt_compression"];
  const std::string who = "buffer view " + std::to_string(view_index) + ": EXT_meshopt_compression";
  if (!ext.is_object()) import.fail(who + " is not an object");
  auto integer = [&](const char* key, bool required, uint64_t fallback) -> uint64_t {
    if (!ext.contains(key)) {
      if (required) import.fail(who + " needs " + key);
      return fallback;
    }
    if (!ext[key].is_number_unsigned()) import.fail(who + "'s " + key + " must be a non-negative integer");
    return ext[key].get<uint64_t>();
  };
  const uint64_t buffer = integer("buffer", true, 0), offset = integer("byteOffset", false, 0),
                 length = integer("byteLength", true, 0), stride = integer("byteStride", true, 0),
                 count = integer("count", true, 0);
  const std::string mode = ext.value("mode", std::string()), filter = ext.value("filter", std::string("NONE"));
  if (buffer >= model.buffers.size())
    import.fail(who + " names buffer " + std::to_string(buffer) + ", which does not exist");
  if (import.meshopt_fallbacks.count(static_cast<int>(buffer)))
    import.fail(who + " reads its data from a fallback buffer");
  const std::vector<unsigned char>& source = model.buffers[buffer].data;
  if (offset > source.size() || length > source.size() - offset)
    import.fail(who + "'s data lies beyond the end of buffer " + std::to_string(buffer));
  if (count > (uint64_t{1} << 28)) import.fail(who + " has an implausible count");
  const unsigned char* in = source.data() + offset;
  std::vector<unsigned char> out;
  int status = -1;
  if (mode == "ATTRIBUTES") {
    if (stride == 0 || stride > 256 || stride % 4 != 0)
      import.fail(who + ": ATTRIBUTES need a byteStride that is a multiple of 4 up to 256");
    import.decoded.take(count * stride, who);
    out.resize(count * stride);
    status = meshopt_decodeVertexBuffer(out.data(), count, stride, in, length);
    if (status == 0 && filter == "OCTAHEDRAL") {
      if (stride != 4 && stride != 8) import.fail(who + ": the OCTAHEDRAL filter needs a byteStride of 4 or 8");
      meshopt_decodeFilterOct(out.data(), count, stride);
    } else if (status == 0 && filter == "QUATERNION") {
      if (stride != 8) import.fail(who + ": the QUATERNION filter needs a byteStride of 8");
      meshopt_decodeFilterQuat(out.data(), count, stride);
    } else if (status == 0 && filter == "EXPONENTIAL") {
      meshopt_decodeFilterExp(out.data(), count, stride);
    } else if (filter != "NONE") {
      if (status == 0) import.fail(who + ": unknown filter \"" + filter + "\"");
    }
  } else if (mode == "TRIANGLES" || mode == "INDICES") {
    if (stride != 2 && stride != 4) import.fail(who + ": " + mode + " need a byteStride of 2 or 4");
    if (filter != "NONE") import.fail(who + ": " + mode + " take no filter");
    if (mode == "TRIANGLES" && count % 3 != 0) import.fail(who + ": TRIANGLES need a count that is a multiple of 3");
    import.decoded.take(count * stride, who);
    out.resize(count * stride);
    status = mode == "TRIANGLES" ? meshopt_decodeIndexBuffer(out.data(), count, stride, in, length)
                                 : meshopt_decodeIndexSequence(out.data(), count, stride, in, length);
  } else {
    import.fail(who + ": mode must be ATTRIBUTES, TRIANGLES or INDICES");
  }
  if (status != 0) import.fail(who + " cannot be decoded (its data is malformed)");
  // The view now reads the decoded bytes: a buffer of their own, the view's declared range over it.
  tinygltf::Buffer decoded;
  decoded.data = std::move(out);
  if (view.byteLength > decoded.data.size())
    import.fail(who + ": the view's byteLength is more than its " + std::to_string(count) + " decoded elements");
  view.buffer = static_cast<int>(model.buffers.size());
  view.byteOffset = 0;
  if (view.byteStride == 0 && mode == "ATTRIBUTES") view.byteStride = stride;
  model.buffers.push_back(std::move(decoded));
}

}  // namespace

void decode_compressed_geometry(Import& import) {
  tinygltf::Model& model = import.model;
  // meshopt first: a Draco stream could itself sit in a meshopt-compressed view.
  const size_t views = model.bufferViews.size();
  for (size_t v = 0; v < views; ++v) {
    import.check_stop();
    if (parse_extensions(model.bufferViews[v].extensions_json_string).contains("EXT_meshopt_compression"))
      decode_meshopt_view(import, static_cast<int>(v));
    else if (import.meshopt_fallbacks.count(model.bufferViews[v].buffer))
      import.fail("buffer view " + std::to_string(v) + " reads a fallback buffer of EXT_meshopt_compression " +
                  "without that extension");
  }
  for (size_t m = 0; m < model.meshes.size(); ++m)
    for (size_t p = 0; p < model.meshes[m].primitives.size(); ++p) {
      import.check_stop();
      if (parse_extensions(model.meshes[m].primitives[p].extensions_json_string).contains("KHR_draco_mesh_compression"))
        decode_draco_primitive(import, static_cast<int>(m), p);
    }
}

}  // namespace tessera::gltf
