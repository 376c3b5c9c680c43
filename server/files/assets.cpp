#include "server/files/assets.h"

#include <openssl/evp.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <fstream>
#include <set>
#include <system_error>

#include "proto/asset_path.h"
#include "renderer/gltf/container.h"
#include "renderer/gltf/loader.h"
#include "renderer/scene_error.h"
#include "renderer/scene_loader.h"
#include "server/base/file_io.h"

namespace tessera::server {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::atomic<uint64_t> g_counter{0};
constexpr const char* kMetaFile = ".asset.json";  // a leading dot: no upload can name it

std::string lower_ext(const std::string& name) {
  std::string e = fs::path(name).extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

Problem invalid(const std::string& detail) {
  return Problem{422, detail, std::nullopt};
}

std::string read_file(const fs::path& p) {
  std::error_code ec;
  const auto size = fs::file_size(p, ec);
  std::ifstream in(p, std::ios::binary);
  if (ec || !in) return {};
  std::string bytes(size, '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(size));
  bytes.resize(static_cast<size_t>(in.gcount()));
  return bytes;
}

// The JSON of an uploaded glTF's main file `name`, read back from `file`: a .glb's JSON chunk, its container
// checked, or a .gltf parsed as it is read (its text, as large as the asset with data: URIs, is not held beside the
// document). Or why it is refused.
std::variant<json, Problem> read_gltf_json(const fs::path& file, const std::string& name) {
  json doc;
  if (lower_ext(name) == ".glb") {
    const std::string bytes = read_file(file);
    auto chunks = parse_glb(bytes);
    if (auto* problem = std::get_if<std::string>(&chunks)) return invalid(name + ": " + *problem);
    doc = json::parse(std::get<GlbChunks>(chunks).json, nullptr, false);
  } else {
    std::ifstream in(file, std::ios::binary);
    doc = json::parse(in, nullptr, false);
  }
  if (doc.is_discarded() || !doc.is_object()) return invalid(name + ": the glTF JSON does not parse");
  return doc;
}

// Nothing, or why the glTF `doc` of main file `name` is refused: every URI of its buffers and images is a data: URI
// or names another file of the upload (`names`).
std::optional<Problem> check_gltf_uris(const json& doc, const std::string& name, const std::set<std::string>& names) {
  for (const char* list : {"buffers", "images"}) {
    auto it = doc.find(list);
    if (it == doc.end() || !it->is_array()) continue;
    for (size_t i = 0; i < it->size(); ++i) {
      const json& item = (*it)[i];
      if (!item.is_object() || !item.contains("uri")) continue;
      const std::string where = name + ": " + list + "[" + std::to_string(i) + "].uri ";
      if (!item["uri"].is_string()) return invalid(where + "is not a string");
      const std::string& uri = item["uri"].get_ref<const std::string&>();
      if (proto::is_data_uri(uri)) continue;
      const std::string shown = "\"" + uri.substr(0, 200) + "\"";
      const proto::AssetPath file = proto::asset_path_from_uri(uri);
      if (!file.problem.empty()) return invalid(where + shown + " refused: " + file.problem);
      if (!names.count(file.path) || file.path == name) return invalid(where + shown + " names no file of this upload");
    }
  }
  return std::nullopt;
}

// The glTF's own JSON, syntax and every URI, read back from the upload's temp dir once its bytes were let go.
std::optional<Problem> check_gltf_json(const fs::path& file, const std::string& name,
                                       const std::set<std::string>& names) {
  auto doc = read_gltf_json(file, name);
  if (auto* problem = std::get_if<Problem>(&doc)) return *problem;
  return check_gltf_uris(std::get<json>(doc), name, names);
}

// Whole and on the disk before the directory is renamed into place: an asset's id promises its content. Throws
// std::system_error with the errno (ENOSPC on a full disk).
void write_file(const fs::path& p, std::string_view bytes) {
  if (int error = write_file_synced(p, bytes); error != 0)
    throw std::system_error(error, std::generic_category(), "cannot write " + p.filename().string());
}

// Frees the upload's bytes once they are on disk: the check loads the asset from its files, and the upload is not
// held in memory beside what the loader makes of it.
void release_bytes(std::vector<UploadFile>& files) {
  for (UploadFile& f : files) std::string().swap(f.bytes);
}

// The answer to an upload that ran out of room while it was written (the disk filled after the --min-free-disk
// check, or a quota): 507 like the check's, not a fault of the daemon.
Problem out_of_space(const std::error_code& ec) {
  return insufficient_storage("the data directory's disk ran out of space while the asset was written (" +
                              ec.message() + ")");
}

}  // namespace

json AssetInfo::to_json() const {
  return {{"id", id}, {"kind", kind}, {"files", files}, {"main", main}, {"bytes", bytes}};
}

bool AssetInfo::owned_by(const std::string& name) const {
  return std::find(owners.begin(), owners.end(), name) != owners.end();
}

bool is_asset_file_name(const std::string& name) {
  // As a URI inside the asset may name it (proto/asset_path.h), already normalised: "textures/wood.png" and
  // "Normal Map.png" are names, "./x.png", "a//b", "../x" and ".hidden" are not.
  const proto::AssetPath file = proto::asset_path(name);
  return file.problem.empty() && file.path == name;
}

bool is_asset_id(const std::string& s) {
  return s.size() == 64 &&
         std::all_of(s.begin(), s.end(), [](char c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'); });
}

std::string sha256_hex(std::string_view bytes) {
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int n = 0;
  EVP_Digest(bytes.data(), bytes.size(), md, &n, EVP_sha256(), nullptr);
  static const char* hex = "0123456789abcdef";
  std::string out;
  for (unsigned int i = 0; i < n; ++i) {
    out += hex[md[i] >> 4];
    out += hex[md[i] & 15];
  }
  return out;
}

DirectoryAssetStore::DirectoryAssetStore(const fs::path& data_dir, AssetCheckOptions check, bool owner)
    : root_(data_dir / "assets"), check_(std::move(check)) {
  if (!owner) return;
  fs::create_directories(root_);
  // Temp dirs of uploads a crash interrupted.
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(root_, ec))
    if (e.path().filename().string().rfind(".tmp-", 0) == 0) fs::remove_all(e.path(), ec);
}

std::variant<StoredAsset, Problem> DirectoryAssetStore::store(std::vector<UploadFile> files, const std::string& owner) {
  if (files.empty()) return Problem{400, "the upload holds no file", std::nullopt};
  if (files.size() > 256) return invalid("an upload holds at most 256 files");
  std::set<std::string> names;
  for (const UploadFile& f : files) {
    if (!is_asset_file_name(f.name)) {
      const proto::AssetPath file = proto::asset_path(f.name);
      return invalid("file name \"" + f.name.substr(0, 200) + "\" is refused: " +
                     (file.problem.empty() ? "not normalised (it names \"" + file.path + "\")" : file.problem));
    }
    if (!names.insert(f.name).second) return invalid("file name \"" + f.name + "\" appears twice");
    if (f.bytes.empty()) return invalid(f.name + ": empty file");
  }
  std::sort(files.begin(), files.end(), [](const UploadFile& a, const UploadFile& b) { return a.name < b.name; });

  // The main file, at the top of the upload (not in a subfolder), decides the kind.
  std::vector<const UploadFile*> scenes, maps, grids;
  for (const UploadFile& f : files) {
    if (f.name.find('/') != std::string::npos) continue;
    const std::string e = lower_ext(f.name);
    if (e == ".glb" || e == ".gltf") scenes.push_back(&f);
    if (e == ".hdr" || e == ".exr") maps.push_back(&f);
    if (e == ".vdb") grids.push_back(&f);
  }
  AssetInfo info;
  info.owners = {owner};
  if (scenes.size() == 1) {
    info.kind = "gltf";
    info.main = scenes[0]->name;
  } else if (scenes.empty() && maps.size() == 1 && files.size() == 1) {
    info.kind = "environment";
    info.main = maps[0]->name;
  } else if (scenes.empty() && grids.size() == 1 && files.size() == 1) {
    info.kind = "volume";
    info.main = grids[0]->name;
  } else {
    return invalid(
        "an upload holds one .glb, or one .gltf with the files it references, or one .hdr or .exr environment map, "
        "or one .vdb volume");
  }
  for (const UploadFile& f : files) {
    info.files.push_back(f.name);
    info.bytes += f.bytes.size();
  }

  // The id is the hash of the upload's names and contents: uploads of the same bytes under the same names share one
  // asset (and its owners list), while the same bytes under another name are another asset, so that an upload never
  // answers with the names another user gave.
  std::string manifest;
  for (const UploadFile& f : files) manifest += f.name + "\t" + sha256_hex(f.bytes) + "\n";
  info.id = sha256_hex(manifest);
  const auto known = [&]() -> std::optional<StoredAsset> {
    std::lock_guard<std::mutex> lock(owners_mutex_);
    auto existing = get(info.id);
    if (!existing) return std::nullopt;
    if (existing->owned_by(owner)) return StoredAsset{*existing, false};
    existing->owners.push_back(owner);
    if (!write_meta(*existing)) return std::nullopt;
    return StoredAsset{*existing, true};
  };
  if (auto existing = known()) return *existing;

  const fs::path temp = root_ / (".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(g_counter.fetch_add(1)));
  std::error_code ec;
  try {
    fs::create_directories(temp);
    for (const UploadFile& f : files) {
      fs::create_directories((temp / f.name).parent_path());  // a subfolder of the asset
      write_file(temp / f.name, f.bytes);
    }
    release_bytes(files);
    if (info.kind == "gltf") {
      if (auto problem = check_gltf_json(temp / info.main, info.main, names)) {
        fs::remove_all(temp, ec);
        return *problem;
      }
    }
    // The asset as the renderer will load it: a malformed buffer or accessor is refused now, not at render time.
    SceneLoadOptions options;
    options.build = false;
    options.max_gltf_instances = check_.max_gltf_instances;
    options.stop = check_.stop;
    options.resolve_asset = [&](const std::string&, const std::string&) { return temp / info.main; };
    json scene;
    if (info.kind == "gltf") {
      scene = {{"gltf", "upload"}};
    } else if (info.kind == "volume") {
      // The grid a job names by default ("density", else the first float grid): the file must hold one.
      scene = {{"materials", {{"boundary", {{"type", "interface"}}}}},
               {"objects",
                {{{"shape", "sphere"},
                  {"center", {0, 0, 0}},
                  {"radius", 1},
                  {"material", "boundary"},
                  {"medium", {{"grid", "upload"}}}}}},
               {"camera", {{"from", {0, 0, 3}}, {"to", {0, 0, 0}}}}};
    } else {
      scene = {{"objects", json::array()},
               {"camera", {{"from", {0, 0, 1}}, {"to", {0, 0, 0}}}},
               {"environment", {{"map", "upload"}}}};
    }
    try {
      if (check_.load)
        check_.load(scene, temp / info.main);
      else
        load_scene(scene, "", options);
    } catch (const SceneError& e) {
      fs::remove_all(temp, ec);
      // The loader names files by their temp path; the client knows them by name.
      std::string what = e.what();
      for (size_t at; (at = what.find(temp.string() + "/")) != std::string::npos;)
        what.erase(at, temp.string().size() + 1);
      return invalid(info.main + ": " + what);
    } catch (const LoadStopped&) {
      fs::remove_all(temp, ec);
      return stopping_problem();
    }
    json meta = info.to_json();
    meta["owners"] = info.owners;
    write_file(temp / kMetaFile, meta.dump());
    fs::rename(temp, root_ / info.id, ec);
    if (ec) {  // the same upload won a race, or the disk is full
      const std::error_code rename_error = ec;
      fs::remove_all(temp, ec);
      if (auto existing = known()) return *existing;
      if (is_out_of_space(rename_error)) return out_of_space(rename_error);
      return Problem{500, "cannot store the asset", std::nullopt};
    }
  } catch (const std::exception& e) {
    fs::remove_all(temp, ec);
    // std::filesystem's errors (creating the temp dir) are system_errors too.
    if (const auto* se = dynamic_cast<const std::system_error*>(&e); se && is_out_of_space(se->code()))
      return out_of_space(se->code());
    throw;
  }
  return StoredAsset{info, true};
}

std::optional<AssetInfo> DirectoryAssetStore::get(const std::string& id) const {
  if (!is_asset_id(id)) return std::nullopt;
  const fs::path meta_path = root_ / id / kMetaFile;
  std::error_code ec;
  if (!fs::is_regular_file(meta_path, ec)) return std::nullopt;
  json meta = json::parse(read_file(meta_path), nullptr, false);
  if (!meta.is_object()) return std::nullopt;
  AssetInfo info;
  info.id = id;
  info.kind = meta.value("kind", "");
  info.main = meta.value("main", "");
  info.bytes = meta.value("bytes", uint64_t{0});
  if (meta.contains("owners") && meta["owners"].is_array()) {
    for (const json& o : meta["owners"])
      if (o.is_string()) info.owners.push_back(o.get<std::string>());
  } else if (meta.contains("owner") && meta["owner"].is_string()) {  // stored by a version with one owner
    info.owners.push_back(meta["owner"].get<std::string>());
  }
  if (meta.contains("files") && meta["files"].is_array())
    for (const json& f : meta["files"])
      if (f.is_string()) info.files.push_back(f.get<std::string>());
  return info;
}

bool DirectoryAssetStore::write_meta(const AssetInfo& info) {
  json meta = info.to_json();
  meta["owners"] = info.owners;
  const fs::path dir = root_ / info.id;
  const fs::path temp = dir / (std::string(kMetaFile) + ".tmp-" + std::to_string(g_counter.fetch_add(1)));
  std::error_code ec;
  if (write_file_synced(temp, meta.dump()) != 0) {
    fs::remove(temp, ec);
    return false;
  }
  fs::rename(temp, dir / kMetaFile, ec);
  if (ec) fs::remove(temp, ec);
  return !ec;
}

bool DirectoryAssetStore::remove(const std::string& id, const std::optional<std::string>& owner) {
  const fs::path doomed = root_ / (".tmp-del-" + std::to_string(g_counter.fetch_add(1)));
  {
    std::lock_guard<std::mutex> lock(owners_mutex_);
    auto info = get(id);
    if (!info) return false;
    if (owner) {
      auto it = std::find(info->owners.begin(), info->owners.end(), *owner);
      if (it == info->owners.end()) return false;
      info->owners.erase(it);
      if (!info->owners.empty()) return write_meta(*info);
    }
    // Renamed away first (and under the lock, so that no upload of the same content is given it meanwhile), so a
    // job never sees half an asset.
    std::error_code ec;
    fs::rename(root_ / id, doomed, ec);
    if (ec) return false;
  }
  std::error_code ec;
  fs::remove_all(doomed, ec);
  return true;
}

std::optional<fs::path> DirectoryAssetStore::main_file(const std::string& id, const std::string& kind) const {
  auto info = get(id);
  if (!info || info->kind != kind || !is_asset_file_name(info->main) || info->main.find('/') != std::string::npos)
    return std::nullopt;
  return root_ / id / info->main;
}

std::function<fs::path(const std::string&, const std::string&)> asset_resolver(const AssetStore& assets,
                                                                               std::optional<std::string> owner) {
  return [&assets, owner](const std::string& ref, const std::string& pointer) -> fs::path {
    const auto ends_with = [&](std::string_view tail) {
      return pointer.size() >= tail.size() && pointer.compare(pointer.size() - tail.size(), tail.size(), tail) == 0;
    };
    const std::string kind = ends_with("/map") ? "environment" : ends_with("/grid") ? "volume" : "gltf";
    if (!is_asset_id(ref)) throw SceneError(pointer, "must be an asset id (64 hex digits) from POST /v1/assets");
    auto info = assets.get(ref);
    if (info && owner && !info->owned_by(*owner)) info.reset();  // another user's asset is unknown
    auto path = info ? assets.main_file(ref, kind) : std::nullopt;
    if (!path) {
      throw SceneError(pointer, info ? "asset " + ref + " is a " + info->kind + " asset, not a " + kind + " asset"
                                     : "no asset " + ref + " (upload it with POST /v1/assets)");
    }
    return *path;
  };
}

}  // namespace tessera::server
