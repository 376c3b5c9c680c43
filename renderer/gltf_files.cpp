// Reading a glTF asset: its container (.gltf JSON or .glb, renderer/gltf_container.h), the files it names, confined
// to its own folder (proto/asset_path.h), the extensions it requires, and its images.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <fstream>

#include "proto/asset_path.h"
#include "renderer/gltf_container.h"
#include "renderer/gltf_internal.h"
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

}  // namespace

json parse_extensions(const std::string& text) {
  if (text.empty()) return json::object();
  json j = json::parse(text, nullptr, false);
  return j.is_object() ? j : json::object();
}

void read_asset(Import& import) {
  const std::filesystem::path& path = import.path;
  const std::string& pointer = import.pointer;
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
  import.doc = container_json(bytes, &binary, pointer);
  json& doc = import.doc;

  // EXT_meshopt_compression's fallback buffers (the extension's specification, "Fallback buffers") hold data only
  // for loaders without the extension, and may have no URI: they are not read (a one-byte stand-in for tinygltf), and
  // nothing may read them but the compressed views that replace them (decode_compressed_geometry).
  if (doc.contains("buffers") && doc["buffers"].is_array())
    for (size_t i = 0; i < doc["buffers"].size(); ++i) {
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
    for (json& mesh : doc["meshes"])
      if (mesh.is_object() && mesh.contains("primitives") && mesh["primitives"].is_array())
        for (json& prim : mesh["primitives"])
          if (prim.is_object() && prim.contains("indices") && prim.contains("extensions") &&
              prim["extensions"].is_object() && prim["extensions"].contains("KHR_draco_mesh_compression")) {
            prim.erase("indices");
            rewritten = true;
          }

  // Every file the asset names must be inside its own folder (proto/asset_path.h), before tinygltf resolves any: the
  // URIs are decoded and normalised here, and handed to tinygltf encoded as it decodes them.
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
        import.warn("extension " + e.get<std::string>() + " is not supported and was ignored");

  tinygltf::TinyGLTF loader;
  FsContext fs_ctx{std::filesystem::weakly_canonical(path.parent_path()), size_t{1} << 31};
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

  import.tinygltf_warnings = std::move(warn);
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
