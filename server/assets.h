// Uploaded assets (issue 4): a glTF 2.0 asset (.glb, or a .gltf with its buffers and images) or an equirectangular
// .hdr/.exr environment map, stored content-addressed under <data>/assets/<id>/ and referenced by jobs by id.
// The id is the sha256 of the file (one file) or of a canonical manifest of (file name, sha256) pairs, sorted by
// name (several files). Everything is checked before it is stored: file names are plain, a .glb's container is
// consistent, a .gltf is JSON, every URI inside passes gltf_uri_problem() and names a file of the same upload (or is
// a data: URI), and the asset loads as the renderer will load it. A directory appears whole (temp dir, rename).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "server/problem.h"

namespace tessera::server {

struct UploadFile {
  std::string name;   // plain: ^[A-Za-z0-9._-]{1,128}$, no leading dot
  std::string bytes;
};

struct AssetInfo {
  std::string id;     // 64 lowercase hex digits
  std::string kind;   // "gltf" | "environment"
  std::vector<std::string> files;
  std::string main;   // the file a job's reference resolves to
  uint64_t bytes = 0;
  std::string owner;  // who uploaded it first (token name; empty without tokens)
  nlohmann::json to_json() const;
};

struct StoredAsset {
  AssetInfo info;
  bool created = false;  // false: the same content was already stored
};

bool is_plain_file_name(const std::string& name);
bool is_asset_id(const std::string& s);
std::string sha256_hex(std::string_view bytes);

class AssetStore {
 public:
  explicit AssetStore(const std::filesystem::path& data_dir);

  // The asset, stored or found already stored; or why not: 4xx for the upload's fault, 507 when the disk ran out of
  // room while it was written (ENOSPC, EDQUOT, EFBIG). A refused upload leaves no file behind.
  std::variant<StoredAsset, Problem> store(std::vector<UploadFile> files, const std::string& owner);
  std::optional<AssetInfo> get(const std::string& id) const;
  bool remove(const std::string& id);
  // The main file of asset `id` when it is of `kind`.
  std::optional<std::filesystem::path> main_file(const std::string& id, const std::string& kind) const;

 private:
  std::filesystem::path root_;
};

}  // namespace tessera::server
