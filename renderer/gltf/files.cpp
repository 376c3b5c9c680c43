// Reading a glTF asset: its container (.gltf JSON or .glb, renderer/gltf/container.h), the files it names, confined
// to its own folder (proto/asset_path.h), the extensions it requires, and its images.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <array>
#include <fstream>
#include <optional>
#include <string_view>

#include "proto/asset_path.h"
#include "renderer/gltf/container.h"
#include "renderer/gltf/internal.h"
#include "renderer/image_input.h"
#include "renderer/image_io.h"
#include "renderer/thread_pool.h"

namespace tessera::gltf {

namespace {

// Extensions whose meaning tessera renders (or, for KHR_materials_variants-like metadata, safely ignores).
const std::set<std::string> kSupportedExtensions = {
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_transmission",
    "KHR_materials_volume",
    "KHR_materials_specular",
    "KHR_materials_clearcoat",
    "KHR_materials_sheen",
    "KHR_texture_transform",
    "KHR_mesh_quantization",
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_materials_pbrSpecularGlossiness",
    "KHR_materials_variants",
    "KHR_materials_unlit",
    "EXT_mesh_gpu_instancing",
    "KHR_materials_anisotropy",
    "KHR_materials_diffuse_transmission",
    "KHR_materials_iridescence",
    "KHR_materials_dispersion",
};

// ---- confined file access for tinygltf ----

struct FsContext {
  std::filesystem::path folder;  // canonical
  size_t max_bytes;
  // The decoded data: URIs of the document, handed to tinygltf as files named embedded_file_name(index).
  std::vector<std::vector<unsigned char>> embedded;
};

// A name no file of an asset can have (asset paths never start with a dot), for the data: URI `index`.
constexpr std::string_view kEmbeddedPrefix = ".data-uri-";
std::string embedded_file_name(size_t index) {
  return std::string(kEmbeddedPrefix) + std::to_string(index);
}

// The data: URI a path tinygltf asks for names (the asset's folder joined with embedded_file_name), or nothing for
// any other path: read from the path itself, whatever the number of data: URIs.
std::optional<size_t> embedded_index(const FsContext& ctx, const std::string& path) {
  const std::string head = (ctx.folder / kEmbeddedPrefix).string();
  if (path.size() <= head.size() || path.compare(0, head.size(), head) != 0) return std::nullopt;
  size_t index = 0;
  for (size_t i = head.size(); i < path.size(); ++i) {
    if (path[i] < '0' || path[i] > '9' || index > ctx.embedded.size()) return std::nullopt;
    index = index * 10 + static_cast<size_t>(path[i] - '0');
  }
  if (index >= ctx.embedded.size() || path != (ctx.folder / embedded_file_name(index)).string()) return std::nullopt;
  return index;
}

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
  const FsContext& ctx = *static_cast<FsContext*>(user);
  std::filesystem::path p;
  return embedded_index(ctx, path) || inside(ctx, path, &p);
}
std::string fs_expand(const std::string& path, void*) {
  return path;
}
bool fs_read(std::vector<unsigned char>* out, std::string* err, const std::string& path, void* user) {
  FsContext& ctx = *static_cast<FsContext*>(user);
  if (auto index = embedded_index(ctx, path)) {
    out->swap(ctx.embedded[*index]);  // tinygltf keeps it as it is: the decoded bytes are not copied
    return true;
  }
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

// ---- data: URIs ----

// The data: URI headers tinygltf decodes (tinygltf::DecodeDataURI).
constexpr std::string_view kDataUriHeaders[] = {
    "data:application/octet-stream;base64,",
    "data:image/jpeg;base64,",
    "data:image/png;base64,",
    "data:image/bmp;base64,",
    "data:image/gif;base64,",
    "data:text/plain;base64,",
    "data:application/gltf-buffer;base64,",
};

// The header of `uri` among those tinygltf decodes, or an empty view.
std::string_view data_uri_header(std::string_view uri) {
  for (std::string_view header : kDataUriHeaders)
    if (uri.substr(0, header.size()) == header) return header;
  return {};
}

// The bytes of a data: URI as tinygltf::DecodeDataURI decodes them: the base64 after its header up to the first
// character that is not base64 ('=' included), a last group of two or three characters giving one or two bytes.
std::vector<unsigned char> decode_data_uri(std::string_view uri) {
  static constexpr std::string_view kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  // Each character's 6 bits, looked up (the text may be tens of megabytes); 64 for a character not in the alphabet.
  static const std::array<uint8_t, 256> kValue = [] {
    std::array<uint8_t, 256> v;
    v.fill(64);
    for (size_t i = 0; i < kAlphabet.size(); ++i) v[static_cast<unsigned char>(kAlphabet[i])] = static_cast<uint8_t>(i);
    return v;
  }();
  const std::string_view text = uri.substr(data_uri_header(uri).size());
  size_t n = 0;
  while (n < text.size() && kValue[static_cast<unsigned char>(text[n])] < 64) ++n;
  std::vector<unsigned char> out((n / 4) * 3 + (n % 4 > 1 ? n % 4 - 1 : 0));
  uint32_t bits = 0;
  size_t at = 0;
  for (size_t i = 0; i < n; ++i) {
    bits = (bits << 6) | kValue[static_cast<unsigned char>(text[i])];
    if (i % 4 == 3 || i + 1 == n) {
      const size_t group = i % 4 + 1;  // characters in this group: 4, or the last 2 or 3
      bits <<= 6 * (4 - group);
      for (size_t b = 0; b + 1 < group; ++b) out[at++] = static_cast<unsigned char>(bits >> (16 - 8 * b));
      bits = 0;
    }
  }
  return out;
}

// A buffer's byteLength as tinygltf reads it from the document's text (an integer of no sign), or nothing.
std::optional<uint64_t> byte_length(const json& item) {
  const auto length = item.find("byteLength");
  if (length == item.end() || !length->is_number_integer()) return std::nullopt;
  if (!length->is_number_unsigned() && length->get<int64_t>() < 0) return std::nullopt;
  return length->get<uint64_t>();
}

// Decodes the data: URI of a buffer or an image of the document into ctx's files and names that file in its place,
// so that tinygltf reads it from there: tinygltf would decode it from its own copies of the document's text (three of
// them, and the text of the URI is as large as the asset). A URI tinygltf would refuse (no bytes, or not the buffer's
// byteLength) is cut to its header, which tinygltf refuses the same way, naming the URI by its header.
// False for a URI tinygltf does not decode (it reads it as a file name, which it cannot find), left as it is.
bool embed_data_uri(json& item, bool buffer, FsContext& ctx) {
  const std::string& uri = item["uri"].get_ref<const std::string&>();
  const std::string_view header = data_uri_header(uri);
  if (header.empty()) return false;
  std::vector<unsigned char> bytes = decode_data_uri(uri);
  if (bytes.empty() || (buffer && byte_length(item) != bytes.size())) {
    item["uri"] = std::string(header);
    return true;
  }
  item["uri"] = embedded_file_name(ctx.embedded.size());
  ctx.embedded.push_back(std::move(bytes));
  return true;
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
  if (const std::string truncated = truncation(bytes.data(), bytes.size()); !truncated.empty())
    return what + " is " + truncated;
  if (const std::string problem = exr_header_problem(bytes.data(), bytes.size()); !problem.empty())
    return what + " cannot be decoded: " + problem;
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
  auto in = open_image_input(name, &config);
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
std::vector<std::shared_ptr<const ImagePixels>> decode_all(tinygltf::Model* model, size_t max_pixels, bool headers_only,
                                                           const std::string& pointer, const std::stop_token& stop) {
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

// The whole file, or SceneError.
std::vector<unsigned char> read_file_bytes(const std::filesystem::path& path, const std::string& pointer) {
  std::error_code ec;
  auto size = std::filesystem::file_size(path, ec);
  if (ec) throw SceneError(pointer, "the glTF asset cannot be read");
  std::vector<unsigned char> bytes(size);
  std::ifstream in(path, std::ios::binary);
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size));
  if (!in) throw SceneError(pointer, "the glTF asset cannot be read");
  return bytes;
}

// Whether the file is a .glb (is_glb: its first bytes), or SceneError when it cannot be read.
bool file_is_glb(const std::filesystem::path& path, const std::string& pointer) {
  std::error_code ec;
  std::ifstream in(path, std::ios::binary);
  if (!std::filesystem::is_regular_file(path, ec) || !in) throw SceneError(pointer, "the glTF asset cannot be read");
  char magic[4] = {};
  in.read(magic, sizeof magic);
  return is_glb(std::string_view(magic, static_cast<size_t>(in.gcount())));
}

// The JSON chunk of a .glb, the container's framing checked (parse_glb).
json glb_json(const std::vector<unsigned char>& bytes, const std::string& pointer) {
  auto chunks = parse_glb(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  if (auto* problem = std::get_if<std::string>(&chunks))
    throw SceneError(pointer, "the .glb is malformed: " + *problem);
  const std::string_view text = std::get<GlbChunks>(chunks).json;
  json j = json::parse(text.begin(), text.end(), nullptr, false);
  if (j.is_discarded() || !j.is_object()) throw SceneError(pointer, "the .glb's JSON chunk is not valid JSON");
  return j;
}

// The JSON of a .gltf, parsed as it is read from the file: its text (as large as the asset with data: URIs) is not
// held beside the document, whose parse takes about three times the size of its largest string at the peak.
json gltf_json(const std::filesystem::path& path, const std::string& pointer) {
  std::ifstream in(path, std::ios::binary);
  json j = json::parse(in, nullptr, false);
  if (j.is_discarded() || !j.is_object()) throw SceneError(pointer, "the file is neither a .glb nor glTF JSON");
  return j;
}

// One warning names the used extensions tessera ignores: the first few, then how many more (an asset may list any
// number of names).
void warn_unsupported_extensions(Import& import) {
  constexpr size_t kNamed = 8;
  std::set<std::string> unsupported;
  for (const json& e : import.doc["extensionsUsed"]) {
    import.check_stop();
    if (e.is_string() && !kSupportedExtensions.count(e.get<std::string>())) unsupported.insert(e.get<std::string>());
  }
  if (unsupported.empty()) return;
  std::string names;
  size_t named = 0;
  for (const std::string& name : unsupported) {
    if (named == kNamed) break;
    names += (named++ ? ", " : "") + name.substr(0, 64);
  }
  if (unsupported.size() > kNamed) names += " and " + std::to_string(unsupported.size() - kNamed) + " more";
  import.warn((unsupported.size() == 1 ? "extension " + names + " is not supported and was ignored"
                                       : "extensions " + names + " are not supported and were ignored"));
}

}  // namespace

json parse_extensions(const std::string& text) {
  if (text.empty()) return json::object();
  json j = json::parse(text, nullptr, false);
  return j.is_object() ? j : json::object();
}

void read_asset(Import& import) {
  const std::filesystem::path& path = import.path;
  const std::string& pointer = import.pointer;
  const bool binary = file_is_glb(path, pointer);
  std::vector<unsigned char> bytes;  // what tinygltf is given: the .glb, or the .gltf's text
  if (binary) {
    bytes = read_file_bytes(path, pointer);
    import.doc = glb_json(bytes, pointer);
  } else {
    import.doc = gltf_json(path, pointer);
  }
  json& doc = import.doc;
  FsContext fs_ctx{std::filesystem::weakly_canonical(path.parent_path()), size_t{1} << 31, {}};

  // EXT_meshopt_compression's fallback buffers (the extension's specification, "Fallback buffers") hold data only
  // for loaders without the extension, and may have no URI: they are not read (a one-byte stand-in for tinygltf), and
  // nothing may read them but the compressed views that replace them (decode_compressed_geometry).
  if (doc.contains("buffers") && doc["buffers"].is_array())
    for (size_t i = 0; i < doc["buffers"].size(); ++i) {
      import.check_stop();
      json& item = doc["buffers"][i];
      if (!item.is_object() || !item.contains("extensions") || !item["extensions"].is_object()) continue;
      const json& ext = item["extensions"].value("EXT_meshopt_compression", json::object());
      if (!ext.is_object() || ext.value("fallback", false) != true) continue;
      item["uri"] = "data:application/octet-stream;base64,AA==";  // one zero byte: tinygltf wants at least one
      item["byteLength"] = 1;
      import.meshopt_fallbacks.insert(static_cast<int>(i));
    }
  bool rewritten = !import.meshopt_fallbacks.empty();
  // A KHR_draco_mesh_compression primitive's indices are the faces Draco decodes (decode_compressed_geometry); its
  // indices accessor has no data, which tinygltf refuses for indices: the reference is dropped before tinygltf reads
  // the document.
  if (doc.contains("meshes") && doc["meshes"].is_array())
    for (json& mesh : doc["meshes"]) {
      import.check_stop();
      if (mesh.is_object() && mesh.contains("primitives") && mesh["primitives"].is_array())
        for (json& prim : mesh["primitives"])
          if (prim.is_object() && prim.contains("indices") && prim.contains("extensions") &&
              prim["extensions"].is_object() && prim["extensions"].contains("KHR_draco_mesh_compression")) {
            prim.erase("indices");
            rewritten = true;
          }
    }

  // Every file the asset names must be inside its own folder (proto/asset_path.h), before tinygltf resolves any: the
  // URIs are decoded and normalised here, and handed to tinygltf encoded as it decodes them.
  for (const char* section : {"buffers", "images"}) {
    if (!doc.contains(section) || !doc[section].is_array()) continue;
    for (size_t i = 0; i < doc[section].size(); ++i) {
      import.check_stop();
      json& item = doc[section][i];
      if (!item.is_object() || !item.contains("uri")) continue;
      const std::string where = std::string(section) + "[" + std::to_string(i) + "]";
      if (!item["uri"].is_string()) throw SceneError(pointer, where + ".uri must be a string");
      const std::string& uri = item["uri"].get_ref<const std::string&>();
      if (proto::is_data_uri(uri)) {
        rewritten = embed_data_uri(item, section == std::string_view("buffers"), fs_ctx) || rewritten;
        continue;
      }
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
  } else if (!binary) {
    bytes = read_file_bytes(path, pointer);
  }
  // Required extensions we cannot honour fail the job; optional ones are warnings.
  if (doc.contains("extensionsRequired") && doc["extensionsRequired"].is_array())
    for (const json& e : doc["extensionsRequired"]) {
      import.check_stop();
      if (e.is_string() && !kSupportedExtensions.count(e.get<std::string>()))
        throw SceneError(pointer, "the asset requires the unsupported extension " + e.get<std::string>());
    }
  if (doc.contains("extensionsUsed") && doc["extensionsUsed"].is_array()) warn_unsupported_extensions(import);

  tinygltf::TinyGLTF loader;
  loader.SetFsCallbacks(tinygltf::FsCallbacks{&fs_exists, &fs_expand, &fs_read, &fs_write, &fs_ctx});
  loader.SetImageLoader(&keep_encoded_image, nullptr);
  loader.SetStoreOriginalJSONForExtrasAndExtensions(true);
  tinygltf::Model& model = import.model;
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
  // An image of a data: URI has no file name (as when tinygltf decodes the URI itself): messages name it by index.
  for (tinygltf::Image& image : model.images)
    if (image.uri.rfind(kEmbeddedPrefix, 0) == 0) image.uri.clear();

  import.tinygltf_warnings = std::move(warn);
  // What the import may make beyond what its buffers hold (GltfImportOptions::max_decoded_bytes).
  size_t stored = 0;
  for (const tinygltf::Buffer& buffer : model.buffers) stored += buffer.data.size();
  constexpr size_t kFloor = size_t{256} << 20, kExpansion = 64;
  import.decoded = DecodeBudget(kFloor + kExpansion * stored, import.options.max_decoded_bytes, pointer);
}

void DecodeBudget::take(size_t bytes, const std::string& what) {
  used_ += bytes;
  if (used_ > allowance_)
    throw SceneError(pointer_, what + " would make the asset's decoded geometry larger than " +
                                   std::to_string(allowance_ >> 20) +
                                   " MiB, the limit for an asset of this size (256 MiB plus 64 times its buffers, at "
                                   "most " +
                                   std::to_string(cap_ >> 20) + " MiB)");
}

std::map<std::string, std::shared_ptr<const ImagePixels>> decode_images(Import& import) {
  std::map<std::string, std::shared_ptr<const ImagePixels>> named;
  std::vector<std::shared_ptr<const ImagePixels>> images =
      decode_all(&import.model, import.options.max_texture_pixels, import.options.headers_only, import.pointer,
                 import.options.stop);
  for (size_t i = 0; i < images.size(); ++i)
    if (images[i]) named["image" + std::to_string(i)] = std::move(images[i]);
  return named;
}

}  // namespace tessera::gltf
