// Uploaded assets: a glTF 2.0 asset (.glb, or a .gltf with its buffers and images), an equirectangular .hdr/.exr
// environment map or an OpenVDB volume (.vdb, a medium's grid), stored content-addressed under <data>/assets/<id>/ and
// referenced by jobs by id. The id is the sha256 of the file (one file) or of a canonical manifest of (file name,
// sha256) pairs, sorted by name (several files). Everything is checked before it is stored: file names are asset paths
// (subfolders allowed; the main file at the top), a .glb's container is consistent, a .gltf is JSON, every URI inside
// is accepted by proto/asset_path.h and names a file of the same upload (or is a data: URI), and the asset loads as the
// renderer will load it. A directory appears whole (temp dir, rename).
//
// Content addressing shares the bytes, never the visibility: an asset belongs to each user who uploaded it, and to
// no one else (another user's asset is as unknown as one that does not exist).
#pragma once

#include <filesystem>
#include <functional>
#include <mutex>
#include <optional>
#include <stop_token>
#include <string>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "server/base/problem.h"

namespace tessera::server {

struct UploadFile {
  std::string name;  // is_asset_file_name(): "scene.gltf", "textures/wood.png"
  std::string bytes;
};

struct AssetInfo {
  std::string id;    // 64 lowercase hex digits
  std::string kind;  // "gltf" | "environment" | "volume"
  std::vector<std::string> files;
  std::string main;  // the file a job's reference resolves to
  uint64_t bytes = 0;
  std::vector<std::string> owners;  // who uploaded it (token names; "" without tokens)
  nlohmann::json to_json() const;   // what its owners are shown (never the other owners)
  bool owned_by(const std::string& name) const;
};

struct StoredAsset {
  AssetInfo info;
  bool created = false;  // false: this owner had uploaded the same content before
};

// A name an uploaded file may have: a normalised asset path (proto/asset_path.h), subfolders allowed.
bool is_asset_file_name(const std::string& name);
bool is_asset_id(const std::string& s);
std::string sha256_hex(std::string_view bytes);

// Where assets are kept: an interface, so that every node of a daemon reaches them wherever they are.
class AssetStore {
 public:
  virtual ~AssetStore() = default;

  // The asset, stored or found already stored (`owner` is then added to its owners); or why not: 4xx for the
  // upload's fault, 507 when the disk ran out of room while it was written (ENOSPC, EDQUOT, EFBIG), 503 when the
  // daemon began stopping during the check. A refused upload leaves no file behind.
  virtual std::variant<StoredAsset, Problem> store(std::vector<UploadFile> files, const std::string& owner) = 0;
  virtual std::optional<AssetInfo> get(const std::string& id) const = 0;
  // Takes `owner` off the asset's owners, and removes its files once it has none; without an owner, removes it
  // whatever its owners (an admin). False when there was nothing to remove.
  virtual bool remove(const std::string& id, const std::optional<std::string>& owner = std::nullopt) = 0;
  // The main file of asset `id` when it is of `kind`, as a local file the renderer can open.
  virtual std::optional<std::filesystem::path> main_file(const std::string& id, const std::string& kind) const = 0;
};

// How an upload is checked by loading it as the renderer will.
struct AssetCheckOptions {
  uint64_t max_gltf_instances = 1'000'000;  // SceneLoadOptions::max_gltf_instances
  std::stop_token stop;                     // the daemon stopping: a check under way ends, and the upload is 503
  // Loads the upload's scene as the renderer will (its asset references naming `main_file`), without building it:
  // throws SceneError for what the renderer refuses, LoadStopped once `stop` is asked. The daemon's runs in a worker
  // process (check_asset_in_worker); unset: in this process.
  std::function<void(const nlohmann::json& scene, const std::filesystem::path& main_file)> load;
};

// The assets in the data directory, <data>/assets/<id>/.
class DirectoryAssetStore final : public AssetStore {
 public:
  // The store's owner (the daemon) removes what uploads a crash interrupted left; a reader (a render worker, which
  // only resolves assets) passes `owner` false and changes nothing.
  explicit DirectoryAssetStore(const std::filesystem::path& data_dir, AssetCheckOptions check = {}, bool owner = true);

  std::variant<StoredAsset, Problem> store(std::vector<UploadFile> files, const std::string& owner) override;
  std::optional<AssetInfo> get(const std::string& id) const override;
  bool remove(const std::string& id, const std::optional<std::string>& owner = std::nullopt) override;
  std::optional<std::filesystem::path> main_file(const std::string& id, const std::string& kind) const override;

 private:
  // Rewrites an asset's metadata (its owners) in place, atomically; false when it cannot.
  bool write_meta(const AssetInfo& info);
  std::filesystem::path root_;
  AssetCheckOptions check_;
  std::mutex owners_mutex_;  // owners are read, changed and written back under it
};

// The asset resolver jobs use: a 64-hex asset id to its main file; anything else is a SceneError at `pointer`. With
// an `owner`, only that user's assets resolve (another's is "no asset", as one that does not exist).
std::function<std::filesystem::path(const std::string&, const std::string&)> asset_resolver(
    const AssetStore& assets, std::optional<std::string> owner = std::nullopt);

}  // namespace tessera::server
