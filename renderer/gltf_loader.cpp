#include "renderer/gltf_loader.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <tiny_gltf.h>

#include <array>
#include <cstring>
#include <fstream>
#include <functional>
#include <set>

#include "proto/asset_path.h"
#include "renderer/gltf_container.h"
#include "renderer/image_io.h"
#include "renderer/scene_error.h"
#include "renderer/thread_pool.h"

namespace tessera {

using nlohmann::json;

namespace {

// Extensions whose meaning tessera renders (or, for KHR_materials_variants-like metadata, safely ignores).
const std::set<std::string> kSupportedExtensions = {
    "KHR_lights_punctual",   "KHR_materials_emissive_strength", "KHR_materials_ior",       "KHR_materials_transmission",
    "KHR_materials_volume",  "KHR_materials_specular",          "KHR_materials_clearcoat", "KHR_materials_sheen",
    "KHR_texture_transform", "KHR_mesh_quantization",           "KHR_materials_unlit",     "EXT_mesh_gpu_instancing",
};

using Mat4 = std::array<double, 16>;  // column-major, as glTF stores matrices

Mat4 identity() {
  return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
}

Mat4 multiply(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int c = 0; c < 4; ++c)
    for (int row = 0; row < 4; ++row) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a[k * 4 + row] * b[c * 4 + k];
      r[c * 4 + row] = s;
    }
  return r;
}

Mat4 local_matrix(const tinygltf::Node& node) {
  if (node.matrix.size() == 16) {
    Mat4 m;
    std::copy(node.matrix.begin(), node.matrix.end(), m.begin());
    return m;
  }
  double t[3] = {0, 0, 0}, s[3] = {1, 1, 1}, q[4] = {0, 0, 0, 1};
  if (node.translation.size() == 3) std::copy(node.translation.begin(), node.translation.end(), t);
  if (node.scale.size() == 3) std::copy(node.scale.begin(), node.scale.end(), s);
  if (node.rotation.size() == 4) std::copy(node.rotation.begin(), node.rotation.end(), q);
  double x = q[0], y = q[1], z = q[2], w = q[3];
  // T * R * S (glTF 2.0 spec, 5.25 node.rotation: a unit quaternion (x, y, z, w)).
  double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y + z * w),     2 * (x * z - y * w),
                 2 * (x * y - z * w),     1 - 2 * (x * x + z * z), 2 * (y * z + x * w),
                 2 * (x * z + y * w),     2 * (y * z - x * w),     1 - 2 * (x * x + y * y)};
  Mat4 m{};
  for (int c = 0; c < 3; ++c)
    for (int row = 0; row < 3; ++row) m[c * 4 + row] = r[c * 3 + row] * s[c];
  m[12] = t[0];
  m[13] = t[1];
  m[14] = t[2];
  m[15] = 1;
  return m;
}

Vec3 apply_point(const Mat4& m, const Vec3& p) {
  return Vec3(static_cast<float>(m[0] * p.x + m[4] * p.y + m[8] * p.z + m[12]),
              static_cast<float>(m[1] * p.x + m[5] * p.y + m[9] * p.z + m[13]),
              static_cast<float>(m[2] * p.x + m[6] * p.y + m[10] * p.z + m[14]));
}
Vec3 apply_vector(const Mat4& m, const Vec3& v) {
  return Vec3(static_cast<float>(m[0] * v.x + m[4] * v.y + m[8] * v.z),
              static_cast<float>(m[1] * v.x + m[5] * v.y + m[9] * v.z),
              static_cast<float>(m[2] * v.x + m[6] * v.y + m[10] * v.z));
}
double det3(const Mat4& m) {
  return m[0] * (m[5] * m[10] - m[9] * m[6]) - m[4] * (m[1] * m[10] - m[9] * m[2]) + m[8] * (m[1] * m[6] - m[5] * m[2]);
}
// Inverse transpose of the upper 3x3 (for normals), as a Mat4 without translation.
Mat4 normal_matrix(const Mat4& m) {
  double d = det3(m);
  Mat4 n{};
  if (d == 0) return identity();
  // Cofactor matrix / det = inverse transpose.
  auto a = [&](int row, int col) { return m[col * 4 + row]; };
  double cof[3][3];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      int r1 = (r + 1) % 3, r2 = (r + 2) % 3, c1 = (c + 1) % 3, c2 = (c + 2) % 3;
      cof[r][c] = a(r1, c1) * a(r2, c2) - a(r1, c2) * a(r2, c1);
    }
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) n[c * 4 + r] = cof[r][c] / d;
  n[15] = 1;
  return n;
}

Transform to_transform(const Mat4& m) {
  Transform t;
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 4; ++col) t.m[row][col] = static_cast<float>(m[col * 4 + row]);
  return t;
}

// ---- reading accessors, with every offset checked against the bytes that exist ----

class AccessorReader {
 public:
  AccessorReader(const tinygltf::Model& model, const std::string& pointer) : model_(model), pointer_(pointer) {}

  // Reads accessor `index` as floats, `components` per element (normalised integers are mapped to [0,1] / [-1,1]).
  std::vector<float> floats(int index, int components) const {
    const tinygltf::Accessor& acc = accessor(index);
    int have = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(acc.type));
    if (have != components)
      fail(index, "has " + std::to_string(have) + " components where " + std::to_string(components) + " are needed");
    std::vector<float> out(acc.count * components, 0.0f);
    read(acc, index, [&](size_t i, int c, const unsigned char* p) { out[i * components + c] = to_float(acc, p); });
    return out;
  }

  std::vector<uint32_t> indices(int index, size_t vertex_count) const {
    const tinygltf::Accessor& acc = accessor(index);
    if (acc.type != TINYGLTF_TYPE_SCALAR) fail(index, "indices must be scalars");
    std::vector<uint32_t> out(acc.count);
    read(acc, index, [&](size_t i, int, const unsigned char* p) {
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

  size_t count(int index) const { return accessor(index).count; }

 private:
  [[noreturn]] void fail(int index, const std::string& what) const {
    throw SceneError(pointer_, "accessor " + std::to_string(index) + " " + what);
  }

  const tinygltf::Accessor& accessor(int index) const {
    if (index < 0 || index >= static_cast<int>(model_.accessors.size())) fail(index, "does not exist");
    const tinygltf::Accessor& acc = model_.accessors[index];
    if (acc.count > (size_t{1} << 28)) fail(index, "has an implausible count");
    return acc;
  }

  static float to_float(const tinygltf::Accessor& acc, const unsigned char* p) {
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

  // Calls fn(element, component, bytes) for every component, dense data first, then sparse substitutions.
  template <typename Fn>
  void read(const tinygltf::Accessor& acc, int index, Fn&& fn) const {
    const int comps = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(acc.type));
    const int csize = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(acc.componentType));
    if (comps <= 0 || csize <= 0) fail(index, "has an unknown type or component type");
    const size_t elem = static_cast<size_t>(comps) * csize;
    if (acc.bufferView >= 0) {
      const unsigned char* base;
      size_t stride, available;
      view(acc.bufferView, index, &base, &available, &stride);
      if (stride == 0) stride = elem;
      if (stride < elem) fail(index, "has a byte stride smaller than its element");
      if (acc.count > 0 && (acc.byteOffset > available || (acc.count - 1) * stride + elem > available - acc.byteOffset))
        fail(index, "reads beyond the end of its buffer view");
      for (size_t i = 0; i < acc.count; ++i)
        for (int c = 0; c < comps; ++c) fn(i, c, base + acc.byteOffset + i * stride + static_cast<size_t>(c) * csize);
    } else {
      std::vector<unsigned char> zero(elem, 0);
      for (size_t i = 0; i < acc.count; ++i)
        for (int c = 0; c < comps; ++c) fn(i, c, zero.data() + static_cast<size_t>(c) * csize);
    }
    if (acc.sparse.isSparse) {
      const auto& sp = acc.sparse;
      if (sp.count < 0 || static_cast<size_t>(sp.count) > acc.count) fail(index, "has a bad sparse count");
      const unsigned char *ibase, *vbase;
      size_t iavail, vavail, istride, vstride;
      view(sp.indices.bufferView, index, &ibase, &iavail, &istride);
      view(sp.values.bufferView, index, &vbase, &vavail, &vstride);
      const int isize = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(sp.indices.componentType));
      if (isize <= 0 || static_cast<size_t>(sp.indices.byteOffset) + static_cast<size_t>(sp.count) * isize > iavail ||
          static_cast<size_t>(sp.values.byteOffset) + static_cast<size_t>(sp.count) * elem > vavail)
        fail(index, "has sparse data beyond its buffer views");
      for (int k = 0; k < sp.count; ++k) {
        const unsigned char* ip = ibase + sp.indices.byteOffset + static_cast<size_t>(k) * isize;
        uint32_t target = 0;
        if (isize == 1)
          target = *ip;
        else if (isize == 2) {
          uint16_t s;
          std::memcpy(&s, ip, 2);
          target = s;
        } else
          std::memcpy(&target, ip, 4);
        if (target >= acc.count) fail(index, "has a sparse index beyond its count");
        for (int c = 0; c < comps; ++c)
          fn(target, c, vbase + sp.values.byteOffset + static_cast<size_t>(k) * elem + static_cast<size_t>(c) * csize);
      }
    }
  }

  void view(int view_index, int accessor_index, const unsigned char** base, size_t* length, size_t* stride) const {
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

  const tinygltf::Model& model_;
  std::string pointer_;
};

// ---- confined file access for tinygltf ----

struct FsContext {
  std::filesystem::path folder;  // canonical
  size_t max_bytes;
};

// The file tinygltf asks for (the asset's folder joined with a URI it percent-decoded; URIs reach it as
// uri_from_asset_path() wrote them) as the confined file it names.
bool inside(const FsContext& ctx, const std::string& path, std::filesystem::path* resolved) {
  const std::string prefix = ctx.folder.string() + "/";
  if (path.compare(0, prefix.size(), prefix) != 0) return false;
  const proto::AssetPath relative = proto::asset_path(std::string_view(path).substr(prefix.size()));
  if (!relative.problem.empty()) return false;
  auto file = proto::confined_file(ctx.folder, relative.path);
  if (!file) return false;
  *resolved = *file;
  return true;
}

bool fs_exists(const std::string& path, void* user) {
  std::filesystem::path p;
  return inside(*static_cast<FsContext*>(user), path, &p);
}
std::string fs_expand(const std::string& path, void*) {
  return path;
}
bool fs_read(std::vector<unsigned char>* out, std::string* err, const std::string& path, void* user) {
  const FsContext& ctx = *static_cast<FsContext*>(user);
  std::filesystem::path p;
  if (!inside(ctx, path, &p)) {
    if (err) *err += "cannot read " + path.substr(std::min(path.size(), ctx.folder.string().size() + 1)) + "\n";
    return false;
  }
  std::error_code ec;
  auto size = std::filesystem::file_size(p, ec);
  if (ec || size > ctx.max_bytes) {
    if (err) *err += "cannot read " + p.filename().string() + "\n";
    return false;
  }
  std::ifstream in(p, std::ios::binary);
  out->resize(size);
  in.read(reinterpret_cast<char*>(out->data()), static_cast<std::streamsize>(size));
  return static_cast<bool>(in);
}
bool fs_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err) *err += "writing is not allowed\n";
  return false;
}

// tinygltf hands over each image's encoded bytes (from a buffer view, a data: URI or a file) while it parses; they
// are kept as they are, marked as not yet decoded, and decoded after parsing, all images at once (decode_images).
bool keep_encoded_image(tinygltf::Image* image, const int, std::string*, std::string*, int, int,
                        const unsigned char* bytes, int size, void*) {
  image->image.assign(bytes, bytes + size);
  image->as_is = true;
  return true;
}

// How messages name image `index`: by the URI of its file as the asset writes it (`image "textures/wood.png"`), else
// by its index (an image in a buffer view or a data: URI).
std::string image_label(const tinygltf::Image& image, size_t index) {
  if (!image.uri.empty() && image.uri.rfind("data:", 0) != 0) return "image \"" + image.uri + "\"";
  return "image " + std::to_string(index);
}

// Decodes one image's encoded bytes with OpenImageIO (PNG, JPEG, and whatever else it reads) into 8-bit RGBA, read
// straight into place for three or four channels (`header_only`: only the header is checked, and `out` is left
// alone); returns an empty string, or what is wrong with the image messages call `what`.
std::string decode_image(const std::vector<unsigned char>& bytes, const std::string& what, size_t max_pixels,
                         bool header_only, ImagePixels* out) {
  // A KTX2 container (its 12-byte identifier, KTX 2.0 specification, 3.1), as KHR_texture_basisu uses: no decoder
  // of Debian's reads it, so it is named for what it is rather than failing as a PNG.
  static const unsigned char kKtx2[12] = {0xAB, 'K', 'T', 'X', ' ', '2', '0', 0xBB, '\r', '\n', 0x1A, '\n'};
  if (bytes.size() >= 12 && std::equal(kKtx2, kKtx2 + 12, bytes.begin()))
    return what +
           " is a KTX2 (Basis Universal) image, which tessera cannot decode (KHR_texture_basisu is not "
           "supported): give the asset PNG or JPEG images";
  if (bytes.size() >= 2 && bytes[0] == 0xFF && bytes[1] == 0xD8 && !jpeg_complete(bytes.data(), bytes.size()))
    return what + " is a truncated JPEG (its data ends before the end-of-image marker)";
  if (header_only) {
    // A JPEG's header through libjpeg: OpenImageIO's open would decode every scan of a progressive one.
    if (auto header = jpeg_header(bytes.data(), bytes.size())) {
      if (static_cast<size_t>(header->width) * static_cast<size_t>(header->height) > max_pixels)
        return what + " is too large (" + std::to_string(header->width) + "x" + std::to_string(header->height) +
               " pixels)";
      return {};
    }
  }
  OIIO::Filesystem::IOMemReader reader(const_cast<unsigned char*>(bytes.data()), bytes.size());
  std::string name = "image.png";
  if (bytes.size() >= 2 && bytes[0] == 0xFF && bytes[1] == 0xD8) name = "image.jpg";
  // The proxy goes in the config (OpenImageIO 2.4 ignores the proxy argument when a config is given), with
  // unassociated alpha: glTF colours are not premultiplied, and OpenImageIO would premultiply PNG alpha on read.
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  void* proxy = &reader;
  config.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &proxy);
  auto in = OIIO::ImageInput::open(name, &config);
  if (!in) return what + " cannot be decoded: " + OIIO::geterror();
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 ||
      static_cast<size_t>(spec.width) * static_cast<size_t>(spec.height) > max_pixels)
    return what + " is too large (" + std::to_string(spec.width) + "x" + std::to_string(spec.height) + " pixels)";
  if (header_only) return {};
  const size_t w = static_cast<size_t>(spec.width), h = static_cast<size_t>(spec.height), texels = w * h;
  const int nch = spec.nchannels;
  out->width = spec.width;
  out->height = spec.height;
  out->channels = 4;
  out->data.resize(texels * 4);  // written whole below (not zeroed first)
  bool ok;
  if (nch >= 3) {
    ok = in->read_image(0, 0, 0, std::min(nch, 4), OIIO::TypeDesc::UINT8, out->data.data(), 4, 4 * w);
    if (nch == 3)
      for (size_t i = 0; i < texels; ++i) out->data[i * 4 + 3] = 255;  // opaque where the image has no alpha
  } else {
    // Grey, or grey and alpha: read, then spread the grey over red, green and blue.
    PixelBuffer<unsigned char> grey(texels * nch);
    ok = in->read_image(0, 0, 0, nch, OIIO::TypeDesc::UINT8, grey.data());
    for (size_t i = 0; ok && i < texels; ++i) {
      unsigned char* dst = &out->data[i * 4];
      dst[0] = dst[1] = dst[2] = grey[i * nch];
      dst[3] = nch == 2 ? grey[i * 2 + 1] : 255;  // opaque where the image has no alpha
    }
  }
  if (!ok) return what + " cannot be decoded: " + in->geterror();
  return {};
}

// Decodes every image tinygltf kept encoded, in parallel (decoding is most of a textured asset's load time), freeing
// the encoded bytes as it goes; with `headers_only`, checks their headers and gives 1x1 stand-ins. Throws the first
// problem, by image index, as a SceneError at `pointer`; LoadStopped once `stop` is asked to stop.
std::vector<std::shared_ptr<const ImagePixels>> decode_images(tinygltf::Model* model, size_t max_pixels,
                                                              bool headers_only, const std::string& pointer,
                                                              const std::stop_token& stop) {
  std::vector<std::shared_ptr<const ImagePixels>> decoded(model->images.size());
  run_in_parallel(decoded.size(), [&](size_t i) {
    if (stop.stop_requested()) throw LoadStopped();
    tinygltf::Image& img = model->images[i];
    if (!img.as_is) return;
    const std::string what = image_label(img, i);
    std::string problem = what + " cannot be decoded: it has no bytes";
    auto pixels = std::make_shared<ImagePixels>();
    if (!img.image.empty()) {
      try {
        problem = decode_image(img.image, what, max_pixels, headers_only, pixels.get());
      } catch (const std::exception& e) {  // out of memory for a huge image, or a decoder that throws
        problem = what + " cannot be decoded: " + e.what();
      }
    }
    std::vector<unsigned char>().swap(img.image);
    if (!problem.empty()) throw SceneError(pointer, "the glTF asset is invalid: " + problem);
    decoded[i] = headers_only ? stand_in_image() : std::move(pixels);
  });
  return decoded;
}

json parse_extensions(const std::string& text) {
  if (text.empty()) return json::object();
  json j = json::parse(text, nullptr, false);
  return j.is_object() ? j : json::object();
}

// Reads the JSON part of a .gltf or .glb, checking the binary container's framing (parse_glb).
json container_json(const std::vector<unsigned char>& bytes, bool* binary, const std::string& pointer) {
  const std::string_view view(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  *binary = is_glb(view);
  if (!*binary) {
    json j = json::parse(bytes.begin(), bytes.end(), nullptr, false);
    if (j.is_discarded() || !j.is_object()) throw SceneError(pointer, "the file is neither a .glb nor glTF JSON");
    return j;
  }
  auto chunks = parse_glb(view);
  if (auto* problem = std::get_if<std::string>(&chunks))
    throw SceneError(pointer, "the .glb is malformed: " + *problem);
  const std::string_view text = std::get<GlbChunks>(chunks).json;
  json j = json::parse(text.begin(), text.end(), nullptr, false);
  if (j.is_discarded() || !j.is_object()) throw SceneError(pointer, "the .glb's JSON chunk is not valid JSON");
  return j;
}

// A glTF textureInfo as a tessera texture parameter: {"texture": "#image<i>", uv set, sampler wrap modes,
// KHR_texture_transform, channel, colour space, factor}. Null when the reference is unusable.
json texture_param(const json& doc, const json& info, int channel, bool srgb, const json& factor,
                   std::vector<std::string>* warnings) {
  if (!info.is_object() || !info.contains("index") || !info["index"].is_number_integer()) return nullptr;
  const int index = info["index"].get<int>();
  const json& textures = doc.contains("textures") ? doc["textures"] : json::array();
  if (index < 0 || index >= static_cast<int>(textures.size())) return nullptr;
  const json& tex = textures[index];
  int source = tex.value("source", -1);
  if (tex.contains("extensions") && !tex.contains("source")) {
    if (warnings) warnings->push_back("texture " + std::to_string(index) + " uses only an extension image source");
    return nullptr;
  }
  if (source < 0) return nullptr;
  json p = {
      {"texture", "#image" + std::to_string(source)}, {"factor", factor}, {"colorspace", srgb ? "srgb" : "linear"}};
  if (channel >= 0) p["channel"] = channel;
  int uv = info.value("texCoord", 0);
  auto wrap_name = [](int mode) {
    switch (mode) {
      case 33071:
        return "clamp";
      case 33648:
        return "mirror";
      default:
        return "repeat";
    }
  };
  if (tex.contains("sampler") && tex["sampler"].is_number_integer() && doc.contains("samplers")) {
    int si = tex["sampler"].get<int>();
    if (si >= 0 && si < static_cast<int>(doc["samplers"].size())) {
      const json& sampler = doc["samplers"][si];
      p["wrap"] = wrap_name(sampler.value("wrapS", 10497));
      p["wrap_t"] = wrap_name(sampler.value("wrapT", 10497));
    }
  }
  if (info.contains("extensions") && info["extensions"].contains("KHR_texture_transform")) {
    const json& t = info["extensions"]["KHR_texture_transform"];
    if (t.contains("offset")) p["offset"] = t["offset"];
    if (t.contains("scale")) p["scale"] = t["scale"];
    if (t.contains("rotation")) p["rotation"] = t["rotation"];
    if (t.contains("texCoord")) uv = t.value("texCoord", uv);
  }
  if (uv < 0 || uv > 1) {
    if (warnings) warnings->push_back("TEXCOORD_" + std::to_string(uv) + " is not supported; using TEXCOORD_0");
    uv = 0;
  }
  p["uv"] = uv;
  return p;
}

json number_or(const json& obj, const char* key, double fallback) {
  auto it = obj.find(key);
  return it != obj.end() && it->is_number() ? *it : json(fallback);
}
json rgb_or(const json& obj, const char* key, const json& fallback) {
  auto it = obj.find(key);
  return it != obj.end() && it->is_array() && it->size() >= 3 ? json{(*it)[0], (*it)[1], (*it)[2]} : fallback;
}

// gltf_pbr parameters for glTF material `m` (spec 3.9, appendix B; the KHR_materials_* extensions), textures included.
json material_params(const json& doc, const json& m, std::vector<std::string>* warnings) {
  json p = {{"type", "gltf_pbr"}};
  const json pbr = m.value("pbrMetallicRoughness", json::object());
  const json ext = m.value("extensions", json::object());
  // A parameter that is a constant, or the texture scaled by that constant.
  auto set = [&](const char* key, const json& factor, const json& info, int channel, bool srgb) {
    json tex = texture_param(doc, info, channel, srgb, factor, warnings);
    p[key] = tex.is_null() ? factor : tex;
  };
  if (ext.contains("KHR_materials_unlit")) {
    // KHR_materials_unlit: the surface shows its base colour as it is, lit by nothing. A path tracer gives it that
    // radiance as emission on a surface that reflects nothing (black, no specular), so the camera sees the colour
    // exactly; as an emitter it also lights what is around it, which a viewer's unlit shading does not.
    p["base_color"] = json{0, 0, 0};
    p["metallic"] = 0.0;
    p["specular"] = 0.0;
    set("emission", rgb_or(pbr, "baseColorFactor", {1, 1, 1}), pbr.value("baseColorTexture", json()), -1, true);
    p["one_sided"] = !m.value("doubleSided", false);
    if (warnings)
      warnings->push_back("material \"" + m.value("name", std::string()) +
                          "\": KHR_materials_unlit is rendered as emission of its base colour (it lights its "
                          "surroundings too)");
    return p;
  }
  set("base_color", rgb_or(pbr, "baseColorFactor", {1, 1, 1}), pbr.value("baseColorTexture", json()), -1, true);
  const json mr = pbr.value("metallicRoughnessTexture", json());
  set("metallic", number_or(pbr, "metallicFactor", 1.0), mr, 2, false);
  set("roughness", number_or(pbr, "roughnessFactor", 1.0), mr, 1, false);
  double strength = 1;
  if (ext.contains("KHR_materials_emissive_strength"))
    strength = number_or(ext["KHR_materials_emissive_strength"], "emissiveStrength", 1.0).get<double>();
  json emissive = rgb_or(m, "emissiveFactor", {0, 0, 0});
  if (emissive[0].get<double>() > 0 || emissive[1].get<double>() > 0 || emissive[2].get<double>() > 0) {
    for (auto& c : emissive) c = c.get<double>() * strength;
    set("emission", emissive, m.value("emissiveTexture", json()), -1, true);
    p["one_sided"] = !m.value("doubleSided", false);
  }
  if (ext.contains("KHR_materials_ior")) p["ior"] = number_or(ext["KHR_materials_ior"], "ior", 1.5);
  if (ext.contains("KHR_materials_transmission")) {
    const json& t = ext["KHR_materials_transmission"];
    set("transmission", number_or(t, "transmissionFactor", 0.0), t.value("transmissionTexture", json()), 0, false);
  }
  if (ext.contains("KHR_materials_specular")) {
    const json& t = ext["KHR_materials_specular"];
    set("specular", number_or(t, "specularFactor", 1.0), t.value("specularTexture", json()), 3, false);
    set("specular_color", rgb_or(t, "specularColorFactor", {1, 1, 1}), t.value("specularColorTexture", json()), -1,
        true);
  }
  if (ext.contains("KHR_materials_clearcoat")) {
    const json& t = ext["KHR_materials_clearcoat"];
    set("clearcoat", number_or(t, "clearcoatFactor", 0.0), t.value("clearcoatTexture", json()), 0, false);
    set("clearcoat_roughness", number_or(t, "clearcoatRoughnessFactor", 0.0),
        t.value("clearcoatRoughnessTexture", json()), 1, false);
    if (t.contains("clearcoatNormalTexture") && warnings)
      warnings->push_back("material \"" + m.value("name", std::string()) +
                          "\": clearcoatNormalTexture is not applied (the clearcoat follows the surface's normal)");
  }
  if (ext.contains("KHR_materials_sheen")) {
    const json& t = ext["KHR_materials_sheen"];
    set("sheen_color", rgb_or(t, "sheenColorFactor", {0, 0, 0}), t.value("sheenColorTexture", json()), -1, true);
    set("sheen_roughness", number_or(t, "sheenRoughnessFactor", 0.0), t.value("sheenRoughnessTexture", json()), 3,
        false);
  }
  return p;
}

// The node instances a walk from `roots` makes: a node counts once per path that reaches it. The specification wants
// the hierarchy to be disjoint trees (glTF 2.0, section 3.5.3), where this is the number of nodes; a file whose nodes
// share children is still read (as instancing), and its count grows with the paths: a chain of n nodes each listing
// the next four times makes 4^n. Counted per node once (memoised), in time linear in the nodes and child lists;
// returns at most limit + 1. Throws SceneError at `pointer` for a cycle, a node that does not exist or a hierarchy
// deeper than 256 levels.
uint64_t count_node_instances(const tinygltf::Model& model, const std::vector<int>& roots, uint64_t limit,
                              const std::string& pointer) {
  const int nodes = static_cast<int>(model.nodes.size());
  std::vector<uint64_t> subtree(model.nodes.size(), 0);  // instances a node makes with its descendants; 0: not counted
  std::vector<bool> on_path(model.nodes.size(), false);
  std::function<uint64_t(int, int)> count = [&](int n, int depth) -> uint64_t {
    if (n < 0 || n >= nodes) throw SceneError(pointer, "node " + std::to_string(n) + " does not exist");
    if (on_path[n]) throw SceneError(pointer, "node " + std::to_string(n) + " is its own ancestor (a cycle)");
    if (depth > 256) throw SceneError(pointer, "the node hierarchy is deeper than 256 levels");
    if (subtree[n] == 0) {
      on_path[n] = true;
      uint64_t total = 1;
      for (int child : model.nodes[n].children) total = std::min(total + count(child, depth + 1), limit + 1);
      on_path[n] = false;
      subtree[n] = total;
    }
    return subtree[n];
  };
  uint64_t total = 0;
  for (int root : roots) total = std::min(total + count(root, 0), limit + 1);
  return total;
}

}  // namespace

GltfImport import_gltf(const std::filesystem::path& path, const std::string& pointer, Scene& scene,
                       const GltfImportOptions& options) {
  const auto check_stop = [&options] {
    if (options.stop.stop_requested()) throw LoadStopped();
  };
  GltfImport result;
  std::error_code ec;
  auto size = std::filesystem::file_size(path, ec);
  if (ec) throw SceneError(pointer, "the glTF asset cannot be read");
  std::vector<unsigned char> bytes(size);
  {
    std::ifstream in(path, std::ios::binary);
    in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size));
    if (!in) throw SceneError(pointer, "the glTF asset cannot be read");
  }
  bool binary = false;
  json doc = container_json(bytes, &binary, pointer);

  // Every file the asset names must be inside its own folder (proto/asset_path.h), before tinygltf resolves any: the
  // URIs are decoded and normalised here, and handed to tinygltf encoded as it decodes them.
  bool rewritten = false;
  for (const char* section : {"buffers", "images"}) {
    if (!doc.contains(section) || !doc[section].is_array()) continue;
    for (size_t i = 0; i < doc[section].size(); ++i) {
      json& item = doc[section][i];
      if (!item.is_object() || !item.contains("uri")) continue;
      const std::string where = std::string(section) + "[" + std::to_string(i) + "]";
      if (!item["uri"].is_string()) throw SceneError(pointer, where + ".uri must be a string");
      const std::string uri = item["uri"].get<std::string>();
      if (proto::is_data_uri(uri)) continue;
      const std::string shown = "refused URI \"" + uri.substr(0, 200) + "\" in " + where + ": ";
      const proto::AssetPath file = proto::asset_path_from_uri(uri);
      if (!file.problem.empty()) throw SceneError(pointer, shown + file.problem);
      bool outside = false;
      if (!proto::confined_file(path.parent_path(), file.path, &outside) && outside)
        throw SceneError(pointer, shown + "it resolves outside the asset (a symbolic link)");
      const std::string encoded = proto::uri_from_asset_path(file.path);
      if (encoded != uri) {
        item["uri"] = encoded;
        rewritten = true;
      }
    }
  }
  if (rewritten) {
    // tinygltf reads the URIs from the bytes: give it the document with the rewritten ones.
    const std::string text = doc.dump();
    if (binary) {
      const GlbChunks chunks =
          std::get<GlbChunks>(parse_glb(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size())));
      const std::string glb = make_glb(text, chunks.bin);
      bytes.assign(glb.begin(), glb.end());
    } else {
      bytes.assign(text.begin(), text.end());
    }
  }
  // Required extensions we cannot honour fail the job; optional ones are warnings.
  if (doc.contains("extensionsRequired") && doc["extensionsRequired"].is_array())
    for (const json& e : doc["extensionsRequired"])
      if (e.is_string() && !kSupportedExtensions.count(e.get<std::string>()))
        throw SceneError(pointer, "the asset requires the unsupported extension " + e.get<std::string>());
  if (doc.contains("extensionsUsed") && doc["extensionsUsed"].is_array())
    for (const json& e : doc["extensionsUsed"])
      if (e.is_string() && !kSupportedExtensions.count(e.get<std::string>()))
        result.warnings.push_back("extension " + e.get<std::string>() + " is not supported and was ignored");

  tinygltf::TinyGLTF loader;
  FsContext fs_ctx{std::filesystem::weakly_canonical(path.parent_path()), size_t{1} << 31};
  loader.SetFsCallbacks(tinygltf::FsCallbacks{&fs_exists, &fs_expand, &fs_read, &fs_write, &fs_ctx});
  loader.SetImageLoader(&keep_encoded_image, nullptr);
  loader.SetStoreOriginalJSONForExtrasAndExtensions(true);
  tinygltf::Model model;
  std::string err, warn;
  const std::string base = fs_ctx.folder.string();
  bool ok = binary ? loader.LoadBinaryFromMemory(&model, &err, &warn, bytes.data(),
                                                 static_cast<unsigned int>(bytes.size()), base)
                   : loader.LoadASCIIFromString(&model, &err, &warn, reinterpret_cast<const char*>(bytes.data()),
                                                static_cast<unsigned int>(bytes.size()), base);
  if (!ok) {
    while (!err.empty() && (err.back() == '\n' || err.back() == ' ')) err.pop_back();
    throw SceneError(pointer, "the glTF asset is invalid: " + (err.empty() ? std::string("tinygltf failed") : err));
  }

  // The nodes to render, and how many instances of them the walk will make: bounded before anything is made.
  std::vector<int> roots;
  int scene_index = model.defaultScene >= 0 ? model.defaultScene : (model.scenes.empty() ? -1 : 0);
  if (scene_index >= 0 && scene_index < static_cast<int>(model.scenes.size())) {
    roots = model.scenes[scene_index].nodes;
  } else {
    // No scenes: render every node that is nobody's child.
    std::vector<bool> is_child(model.nodes.size(), false);
    for (const auto& n : model.nodes)
      for (int c : n.children)
        if (c >= 0 && c < static_cast<int>(is_child.size())) is_child[c] = true;
    for (size_t i = 0; i < model.nodes.size(); ++i)
      if (!is_child[i]) roots.push_back(static_cast<int>(i));
  }
  if (count_node_instances(model, roots, options.max_instances, pointer) > options.max_instances)
    throw SceneError(pointer, "the node hierarchy makes more than " + std::to_string(options.max_instances) +
                                  " node instances, the limit (a node counts once per path to it from the scene: "
                                  "children that nodes share multiply)");
  check_stop();

  // Images, decoded once, shared by every texture that uses them (as "#image<i>").
  MaterialContext mctx;
  std::vector<std::shared_ptr<const ImagePixels>> images =
      decode_images(&model, options.max_texture_pixels, options.headers_only, pointer, options.stop);
  for (size_t i = 0; i < images.size(); ++i)
    if (images[i]) mctx.images["image" + std::to_string(i)] = std::move(images[i]);

  // Materials: glTF materials by index, replaced by the job's materials of the same name.
  const MaterialRegistry& registry = MaterialRegistry::builtin();
  const json no_materials = json::array();
  const json& gltf_materials =
      doc.contains("materials") && doc["materials"].is_array() ? doc["materials"] : no_materials;
  std::vector<uint32_t> material_index(model.materials.size());
  for (size_t i = 0; i < model.materials.size(); ++i) {
    check_stop();
    const tinygltf::Material& m = model.materials[i];
    if (auto it = options.material_overrides.find(m.name); !m.name.empty() && it != options.material_overrides.end()) {
      material_index[i] = it->second;
      continue;
    }
    const json& mj = i < gltf_materials.size() && gltf_materials[i].is_object() ? gltf_materials[i] : json::object();
    json params = material_params(doc, mj, &result.warnings);
    if (!registry.has("gltf_pbr")) {
      // Without the metallic-roughness model, keep colour and emission on a diffuse surface.
      json lambert = {{"type", "lambert"}, {"albedo", params.value("base_color", json{0.8, 0.8, 0.8})}};
      for (const char* key : {"emission", "one_sided"})
        if (params.contains(key)) lambert[key] = params[key];
      params = lambert;
    }
    material_index[i] = static_cast<uint32_t>(scene.materials.size());
    const std::string mp = pointer + "/materials/" + std::to_string(i);
    std::unique_ptr<Material> material = registry.create(params, mp, mctx);
    // Coverage (spec 3.9.4): base colour alpha (factor times texture alpha); MASK against alphaCutoff, BLEND
    // stochastically.
    if (m.alphaMode == "MASK" || m.alphaMode == "BLEND") {
      material->alpha_mode = m.alphaMode == "MASK" ? Material::AlphaMode::kMask : Material::AlphaMode::kBlend;
      material->alpha_cutoff = static_cast<float>(m.alphaCutoff);
      const json pbr = mj.value("pbrMetallicRoughness", json::object());
      double a = pbr.contains("baseColorFactor") && pbr["baseColorFactor"].size() == 4
                     ? pbr["baseColorFactor"][3].get<double>()
                     : 1.0;
      json tex = texture_param(doc, pbr.value("baseColorTexture", json()), 3, false, std::clamp(a, 0.0, 1.0), nullptr);
      json holder = {{"alpha", tex.is_null() ? json(std::clamp(a, 0.0, 1.0)) : tex}};
      material->alpha = params::float_param(holder, "alpha", mp, 1.0f, 0.0f, 1.0f, mctx);
    }
    // Normal map (spec 3.9.3): tangent-space, linear, scaled in x and y.
    if (mj.contains("normalTexture")) {
      json tex = texture_param(doc, mj["normalTexture"], -1, false, json{1, 1, 1}, &result.warnings);
      if (!tex.is_null()) {
        json holder = {{"normal", tex}};
        material->normal_map = params::rgb_param(holder, "normal", mp, Rgb(1), 0.0f, 1.0f, mctx).texture;
        material->normal_scale = static_cast<float>(mj["normalTexture"].value("scale", 1.0));
      }
    }
    // KHR_materials_volume: absorption through the object (thickness is a rasteriser's stand-in; a path tracer
    // measures the real distance travelled inside the geometry).
    json ext = parse_extensions(m.extensions_json_string);
    if (ext.contains("KHR_materials_volume")) {
      const json& v = ext["KHR_materials_volume"];
      double distance = v.value("attenuationDistance", 0.0);
      json color = v.value("attenuationColor", json{1, 1, 1});
      if (distance > 0 && color.is_array() && color.size() == 3)
        for (int c = 0; c < 3; ++c) {
          double col = color[c].is_number() ? std::clamp(color[c].get<double>(), 1e-6, 1.0) : 1.0;
          material->volume_sigma_a[c] = static_cast<float>(-std::log(col) / distance);
        }
    }
    scene.materials.push_back(std::move(material));
    scene.material_names.push_back(m.name.empty() ? "gltf:" + std::to_string(i) : m.name);
  }
  // The glTF default material (spec 3.9.6): white, fully rough dielectric... metallic 1 by the spec's defaults.
  uint32_t default_material = kNoLight;
  auto get_default_material = [&]() {
    if (default_material == kNoLight) {
      json params = registry.has("gltf_pbr")
                        ? json{{"type", "gltf_pbr"}, {"base_color", {1, 1, 1}}, {"metallic", 1.0}, {"roughness", 1.0}}
                        : json{{"type", "lambert"}, {"albedo", {1, 1, 1}}};
      default_material = static_cast<uint32_t>(scene.materials.size());
      scene.materials.push_back(registry.create(params, pointer, MaterialContext{}));
      scene.material_names.push_back("gltf:default");
    }
    return default_material;
  };

  AccessorReader reader(model, pointer);
  size_t triangles = scene.triangle_count();
  std::set<int> instanced;
  std::map<int, uint32_t> group_of_mesh;
  std::map<int, size_t> camera_instances;

  // The triangles of glTF mesh `mesh_index` under transform `world` (identity for instanced prototypes).
  // With `joints` (a skin's joint matrices: joint world transform times inverse bind matrix), each vertex is moved by
  // the blend of its JOINTS_0 matrices by WEIGHTS_0 (glTF 2.0, 3.7.3 "Skins"), and `world` is not used.
  auto build_meshes = [&](int mesh_index, const Mat4& world, const std::vector<Mat4>* joints = nullptr) {
    const bool flip = det3(world) < 0;  // a mirroring transform reverses the winding
    const Mat4 nmat = normal_matrix(world);
    std::vector<Mesh> out;
    for (const tinygltf::Primitive& prim : model.meshes[mesh_index].primitives) {
      check_stop();
      if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
          prim.mode != TINYGLTF_MODE_TRIANGLE_FAN) {
        result.warnings.push_back("mesh " + std::to_string(mesh_index) + ": points and lines are not rendered");
        continue;
      }
      auto pos_it = prim.attributes.find("POSITION");
      if (pos_it == prim.attributes.end()) continue;
      Mesh mesh;
      std::vector<float> pos = reader.floats(pos_it->second, 3);
      const size_t nv = pos.size() / 3;
      // Morph targets at the mesh's default weights (glTF 2.0, 3.7.2.2): attribute + sum of weight_k * target_k's
      // displacement, for POSITION, NORMAL and TANGENT (whose targets are 3-vectors added to xyz).
      const std::vector<double>& weights = model.meshes[mesh_index].weights;
      auto morph = [&](std::vector<float>& values, const char* name, int stride) {
        for (size_t k = 0; k < prim.targets.size() && k < weights.size(); ++k) {
          auto it = prim.targets[k].find(name);
          if (it == prim.targets[k].end() || weights[k] == 0) continue;
          if (reader.count(it->second) != nv)
            throw SceneError(pointer, "mesh " + std::to_string(mesh_index) + ": morph target " + std::to_string(k) +
                                          " " + name + " has another count than POSITION");
          const std::vector<float> d = reader.floats(it->second, 3);
          const float w = static_cast<float>(weights[k]);
          for (size_t v = 0; v < nv; ++v)
            for (int c = 0; c < 3; ++c) values[v * stride + c] += w * d[3 * v + c];
        }
      };
      morph(pos, "POSITION", 3);
      std::vector<Mat4> skin_at;  // per vertex, when skinned
      if (joints) {
        auto ji = prim.attributes.find("JOINTS_0"), wi = prim.attributes.find("WEIGHTS_0");
        if (ji == prim.attributes.end() || wi == prim.attributes.end() || reader.count(ji->second) != nv ||
            reader.count(wi->second) != nv)
          throw SceneError(pointer, "mesh " + std::to_string(mesh_index) +
                                        ": a skinned mesh needs JOINTS_0 and WEIGHTS_0 for every vertex");
        const std::vector<float> jv = reader.floats(ji->second, 4), wv = reader.floats(wi->second, 4);
        skin_at.resize(nv);
        for (size_t v = 0; v < nv; ++v) {
          Mat4 m{};
          for (int k = 0; k < 4; ++k) {
            const float w = wv[4 * v + k];
            if (w == 0) continue;
            const size_t j = static_cast<size_t>(jv[4 * v + k]);
            if (j >= joints->size())
              throw SceneError(pointer, "mesh " + std::to_string(mesh_index) + ": JOINTS_0 names joint " +
                                            std::to_string(j) + " of a skin of " + std::to_string(joints->size()));
            for (int e = 0; e < 16; ++e) m[e] += w * (*joints)[j][e];
          }
          skin_at[v] = m;
        }
      }
      auto vertex_world = [&](size_t v) -> const Mat4& { return skin_at.empty() ? world : skin_at[v]; };
      mesh.positions.resize(nv);
      for (size_t v = 0; v < nv; ++v) {
        mesh.positions[v] = apply_point(vertex_world(v), Vec3(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]));
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
          Vec3 wn = apply_vector(skin_at.empty() ? nmat : normal_matrix(skin_at[v]),
                                 Vec3(n[3 * v], n[3 * v + 1], n[3 * v + 2]));
          float len = length(wn);
          mesh.normals[v] = len > 0 ? wn / len : Vec3(0, 0, 1);
        }
      }
      if (int a = attr("TANGENT"); a >= 0 && !mesh.normals.empty()) {
        check_count(a, "TANGENT");
        std::vector<float> t = reader.floats(a, 4);
        morph(t, "TANGENT", 4);
        mesh.tangents.resize(nv);
        mesh.tangent_signs.resize(nv);
        for (size_t v = 0; v < nv; ++v) {
          Vec3 wt = apply_vector(vertex_world(v), Vec3(t[4 * v], t[4 * v + 1], t[4 * v + 2]));
          float len = length(wt);
          mesh.tangents[v] = len > 0 ? wt / len : Vec3(1, 0, 0);
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
      triangles += tri.size() / 3;
      if (triangles > options.max_triangles)
        throw SceneError(pointer,
                         "the asset exceeds the limit of " + std::to_string(options.max_triangles) + " triangles");
      mesh.indices = std::move(tri);
      if (prim.material >= static_cast<int>(model.materials.size()))
        throw SceneError(pointer,
                         "a primitive names material " + std::to_string(prim.material) + ", which does not exist");
      mesh.material = prim.material >= 0 ? material_index[prim.material] : get_default_material();
      if (!mesh.indices.empty()) out.push_back(std::move(mesh));
    }
    return out;
  };

  // EXT_mesh_gpu_instancing: the node's mesh drawn once per instance, at the node's transform times the instance's
  // TRANSLATION * ROTATION * SCALE (each attribute optional; the extension's specification). Empty without it.
  uint64_t gpu_instances_made = 0;
  auto gpu_instance_count = [&](const tinygltf::Node& node) -> size_t {
    const json ext = parse_extensions(node.extensions_json_string);
    if (!ext.contains("EXT_mesh_gpu_instancing")) return 0;
    const json attrs = ext["EXT_mesh_gpu_instancing"].value("attributes", json::object());
    for (const char* key : {"TRANSLATION", "ROTATION", "SCALE"})
      if (attrs.contains(key) && attrs[key].is_number_integer()) return reader.count(attrs[key].get<int>());
    return 0;
  };
  auto gpu_instances = [&](const tinygltf::Node& node, int node_index) -> std::vector<Mat4> {
    const size_t n = gpu_instance_count(node);
    if (n == 0) return {};
    gpu_instances_made += n;
    if (gpu_instances_made > options.max_instances)
      throw SceneError(pointer, "EXT_mesh_gpu_instancing makes more than " + std::to_string(options.max_instances) +
                                    " instances, the limit");
    const json attrs = parse_extensions(node.extensions_json_string)["EXT_mesh_gpu_instancing"]["attributes"];
    auto read = [&](const char* key, int components) {
      std::vector<float> v;
      if (!attrs.contains(key) || !attrs[key].is_number_integer()) return v;
      if (reader.count(attrs[key].get<int>()) != n)
        throw SceneError(pointer, "node " + std::to_string(node_index) + ": EXT_mesh_gpu_instancing's " + key +
                                      " has another count than its other attributes");
      v = reader.floats(attrs[key].get<int>(), components);
      return v;
    };
    const std::vector<float> t = read("TRANSLATION", 3), r = read("ROTATION", 4), sc = read("SCALE", 3);
    std::vector<Mat4> out(n);
    for (size_t i = 0; i < n; ++i) {
      check_stop();
      tinygltf::Node trs;
      if (!t.empty()) trs.translation = {t[3 * i], t[3 * i + 1], t[3 * i + 2]};
      if (!r.empty()) trs.rotation = {r[4 * i], r[4 * i + 1], r[4 * i + 2], r[4 * i + 3]};
      if (!sc.empty()) trs.scale = {sc[3 * i], sc[3 * i + 1], sc[3 * i + 2]};
      out[i] = local_matrix(trs);
    }
    return out;
  };

  std::vector<Mat4> node_world;  // filled before the walk
  std::function<void(int, const Mat4&, int)> visit = [&](int node_index, const Mat4& parent, int depth) {
    if (node_index < 0 || node_index >= static_cast<int>(model.nodes.size()))
      throw SceneError(pointer, "node " + std::to_string(node_index) + " does not exist");
    if (depth > 256) throw SceneError(pointer, "the node hierarchy is deeper than 256 levels (a cycle?)");
    check_stop();
    const tinygltf::Node& node = model.nodes[node_index];
    if (!node.weights.empty() && node.mesh >= 0 && node.mesh < static_cast<int>(model.meshes.size()) &&
        node.weights != model.meshes[node.mesh].weights)
      result.warnings.push_back("node " + std::to_string(node_index) +
                                ": its own morph weights are not applied (the mesh's default weights are)");
    const Mat4 world = multiply(parent, local_matrix(node));

    if (node.mesh >= 0) {
      if (node.mesh >= static_cast<int>(model.meshes.size()))
        throw SceneError(pointer, "node " + std::to_string(node_index) + " names mesh " + std::to_string(node.mesh) +
                                      ", which does not exist");
      // The mesh at transform `at`: an instance of its one object-space copy, or triangles of its own.
      auto place = [&](const Mat4& at) {
        if (instanced.count(node.mesh)) {
          // Shared by several nodes: one object-space copy, one Embree instance per node.
          auto [it, fresh] = group_of_mesh.try_emplace(node.mesh, static_cast<uint32_t>(scene.groups.size()));
          if (fresh) {
            MeshGroup group;
            for (Mesh& m : build_meshes(node.mesh, identity())) {
              m.prototype = true;
              group.meshes.push_back(static_cast<uint32_t>(scene.meshes.size()));
              scene.meshes.push_back(std::move(m));
            }
            scene.groups.push_back(std::move(group));
          }
          Instance inst;
          inst.group = it->second;
          inst.to_world = to_transform(at);
          inst.normal_to_world = to_transform(normal_matrix(at));
          inst.mirrored = det3(at) < 0;
          for (uint32_t m : scene.groups[inst.group].meshes) {
            if (!fresh) triangles += scene.meshes[m].triangle_count();  // build_meshes counted the first
            for (const Vec3& p : scene.meshes[m].positions) result.bounds.extend(inst.to_world.point(p));
          }
          if (triangles > options.max_triangles)
            throw SceneError(pointer,
                             "the asset exceeds the limit of " + std::to_string(options.max_triangles) + " triangles");
          scene.instances.push_back(inst);
        } else {
          for (Mesh& m : build_meshes(node.mesh, at)) {
            for (const Vec3& p : m.positions) result.bounds.extend(p);
            scene.meshes.push_back(std::move(m));
          }
        }
      };
      const std::vector<Mat4> copies = gpu_instances(node, node_index);
      if (node.skin >= 0) {
        // Posed by its joints' node transforms (the scene's, for a still image); the node's own transform is not
        // used (glTF 2.0, 3.7.3).
        if (node.skin >= static_cast<int>(model.skins.size()))
          throw SceneError(pointer, "node " + std::to_string(node_index) + " names a skin that does not exist");
        const tinygltf::Skin& skin = model.skins[node.skin];
        std::vector<float> ibm;
        if (skin.inverseBindMatrices >= 0) ibm = reader.floats(skin.inverseBindMatrices, 16);
        if (!ibm.empty() && ibm.size() != skin.joints.size() * 16)
          throw SceneError(pointer,
                           "skin " + std::to_string(node.skin) + ": inverseBindMatrices has another count than joints");
        std::vector<Mat4> joints(skin.joints.size());
        for (size_t j = 0; j < joints.size(); ++j) {
          const int jn = skin.joints[j];
          if (jn < 0 || jn >= static_cast<int>(node_world.size()))
            throw SceneError(pointer, "skin " + std::to_string(node.skin) + " names a joint that does not exist");
          Mat4 inverse_bind = identity();
          if (!ibm.empty()) std::copy(ibm.begin() + 16 * j, ibm.begin() + 16 * (j + 1), inverse_bind.begin());
          joints[j] = multiply(node_world[jn], inverse_bind);
        }
        for (Mesh& m : build_meshes(node.mesh, identity(), &joints)) {
          for (const Vec3& p : m.positions) result.bounds.extend(p);
          scene.meshes.push_back(std::move(m));
        }
      } else if (copies.empty()) {
        place(world);
      }
      for (const Mat4& local : copies) place(multiply(world, local));
    }

    if (node.camera >= 0 && node.camera < static_cast<int>(model.cameras.size()) &&
        !camera_instances.count(node.camera)) {
      const tinygltf::Camera& cam = model.cameras[node.camera];
      GltfCamera gc;
      gc.name = cam.name;
      // A glTF camera looks down its local -Z with +Y up (spec 3.10).
      gc.desc.from = apply_point(world, Vec3(0, 0, 0));
      gc.desc.to = gc.desc.from + normalize(apply_vector(world, Vec3(0, 0, -1)));
      gc.desc.up = normalize(apply_vector(world, Vec3(0, 1, 0)));
      if (cam.type == "orthographic") {
        gc.desc.projection = CameraDesc::Projection::kOrthographic;
        gc.desc.ortho_height = static_cast<float>(2 * cam.orthographic.ymag);
        if (cam.orthographic.ymag > 0)
          gc.aspect_ratio = static_cast<float>(cam.orthographic.xmag / cam.orthographic.ymag);
      } else {
        gc.desc.fov_deg = static_cast<float>(cam.perspective.yfov * 180 / M_PI);
        gc.aspect_ratio = static_cast<float>(cam.perspective.aspectRatio);
      }
      camera_instances[node.camera] = result.cameras.size();
      result.cameras.push_back(gc);
    }

    json ext = parse_extensions(node.extensions_json_string);
    if (ext.contains("KHR_lights_punctual") && ext["KHR_lights_punctual"].contains("light")) {
      int li =
          ext["KHR_lights_punctual"]["light"].is_number_integer() ? ext["KHR_lights_punctual"]["light"].get<int>() : -1;
      if (li < 0 || li >= static_cast<int>(model.lights.size()))
        throw SceneError(pointer, "node " + std::to_string(node_index) + " names a light that does not exist");
      const tinygltf::Light& l = model.lights[li];
      PunctualLight pl;
      Rgb color(1);
      if (l.color.size() == 3)
        color = Rgb(static_cast<float>(l.color[0]), static_cast<float>(l.color[1]), static_cast<float>(l.color[2]));
      // KHR_lights_punctual units: point and spot in candela, directional in lux; used as W/sr and W/m^2 (the
      // luminous efficacy is a constant factor that exposure absorbs).
      pl.intensity = color * static_cast<float>(l.intensity);
      pl.position = apply_point(world, Vec3(0, 0, 0));
      pl.direction = normalize(apply_vector(world, Vec3(0, 0, -1)));
      if (l.type == "directional") {
        pl.kind = PunctualLight::Kind::kDirectional;
      } else if (l.type == "spot") {
        pl.kind = PunctualLight::Kind::kSpot;
        pl.cos_inner = static_cast<float>(std::cos(l.spot.innerConeAngle));
        pl.cos_outer = static_cast<float>(std::cos(l.spot.outerConeAngle));
      } else {
        pl.kind = PunctualLight::Kind::kPoint;
      }
      result.lights.push_back(pl);
    }

    for (int child : node.children) visit(child, world, depth + 1);
  };

  // Meshes that several nodes reference are instanced, unless they emit (lights are sampled in world space).
  std::map<int, int> references;
  std::function<void(int, int)> census = [&](int n, int depth) {
    if (n < 0 || n >= static_cast<int>(model.nodes.size()) || depth > 256) return;
    check_stop();
    if (model.nodes[n].mesh >= 0)
      references[model.nodes[n].mesh] += static_cast<int>(std::max<size_t>(1, gpu_instance_count(model.nodes[n])));
    for (int c : model.nodes[n].children) census(c, depth + 1);
  };
  for (int r : roots) census(r, 0);
  for (auto [mesh_index, count] : references) {
    if (count < 2 || mesh_index >= static_cast<int>(model.meshes.size())) continue;
    bool emits = false;
    for (const tinygltf::Primitive& prim : model.meshes[mesh_index].primitives)
      if (prim.material >= 0 && prim.material < static_cast<int>(material_index.size()))
        emits = emits || scene.materials[material_index[prim.material]]->emissive();
    if (!emits) instanced.insert(mesh_index);
  }
  // Every node's world transform (of its first path from the scene), for the joints of skins, which need not be
  // ancestors of the meshes they pose.
  node_world.assign(model.nodes.size(), identity());
  {
    std::vector<bool> placed(model.nodes.size(), false);
    std::function<void(int, const Mat4&, int)> walk = [&](int n, const Mat4& parent, int depth) {
      if (n < 0 || n >= static_cast<int>(model.nodes.size()) || depth > 256 || placed[n]) return;
      placed[n] = true;
      node_world[n] = multiply(parent, local_matrix(model.nodes[n]));
      for (int c : model.nodes[n].children) walk(c, node_world[n], depth + 1);
    };
    for (int r : roots) walk(r, identity(), 0);
  }
  for (int r : roots) visit(r, identity(), 0);
  if (!warn.empty()) result.warnings.push_back(warn);
  // Each warning once, in the order first given (a mesh drawn by many nodes says it once).
  std::set<std::string> seen;
  std::vector<std::string> once;
  for (std::string& w : result.warnings)
    if (seen.insert(w).second) once.push_back(std::move(w));
  result.warnings = std::move(once);
  return result;
}

}  // namespace tessera
