// The asset store when the disk runs out of room while an upload is written (the file-size limit, EFBIG, stands in
// for a full disk, ENOSPC, and a quota, EDQUOT): the upload is refused with 507 and the same problem as the
// --min-free-disk check's, and leaves no file behind; with room again, the same upload is stored.
#include <gtest/gtest.h>

#include <cerrno>

#include "server/assets.h"
#include "server/file_io.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// One triangle in a .gltf with its .bin, the .gltf padded to `gltf_bytes` or more (extras are ignored).
std::vector<UploadFile> triangle_upload(size_t gltf_bytes) {
  const float p[9] = {-1, -1, 0, 1, -1, 0, 0, 1, 0};
  const json gltf = {{"asset", {{"version", "2.0"}, {"extras", {{"padding", std::string(gltf_bytes, 'x')}}}}},
                     {"scene", 0},
                     {"scenes", {{{"nodes", {0}}}}},
                     {"nodes", {{{"mesh", 0}}}},
                     {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}}}}}}},
                     {"accessors",
                      {{{"bufferView", 0},
                        {"componentType", 5126},
                        {"count", 3},
                        {"type", "VEC3"},
                        {"min", {-1, -1, 0}},
                        {"max", {1, 1, 0}}}}},
                     {"bufferViews", {{{"buffer", 0}, {"byteLength", 36}}}},
                     {"buffers", {{{"uri", "tri.bin"}, {"byteLength", 36}}}}};
  return {{"tri.gltf", gltf.dump()}, {"tri.bin", std::string(reinterpret_cast<const char*>(p), sizeof p)}};
}

TEST(FileIo, OutOfSpaceIsAFullDiskAQuotaOrAFileSizeLimit) {
  for (int e : {ENOSPC, EDQUOT, EFBIG}) {
    EXPECT_TRUE(is_out_of_space(e)) << e;
    EXPECT_TRUE(is_out_of_space(std::error_code(e, std::system_category()))) << e;
    EXPECT_TRUE(is_out_of_space(std::error_code(e, std::generic_category()))) << e;
  }
  for (int e : {0, EIO, EACCES, EROFS, ENOENT}) EXPECT_FALSE(is_out_of_space(e)) << e;
  EXPECT_FALSE(is_out_of_space(std::make_error_code(std::io_errc::stream)));  // not an errno at all
}

TEST(AssetStore, AnUploadThatRunsOutOfSpaceIs507AndLeavesNothing) {
  test::TempDir dir;
  AssetStore assets(dir.path());
  const fs::path root = dir.path() / "assets";
  std::variant<StoredAsset, Problem> stored;
  {
    test::FileSizeLimit limit(64 << 10);
    stored = assets.store(triangle_upload(256 << 10), "alice");
  }
  ASSERT_TRUE(std::holds_alternative<Problem>(stored)) << std::get<StoredAsset>(stored).info.id;
  const Problem& problem = std::get<Problem>(stored);
  EXPECT_EQ(problem.status, 507) << problem.detail;
  EXPECT_EQ(problem.type(), "https://tessera.dev/problems/insufficient-storage");
  EXPECT_FALSE(problem.pointer);
  EXPECT_NE(problem.detail.find("ran out of space while the asset was written (File too large)"), std::string::npos)
      << problem.detail;
  // The wording of the --min-free-disk refusal (insufficient_storage()).
  EXPECT_NE(problem.detail.find("nothing was stored"), std::string::npos) << problem.detail;
  EXPECT_TRUE(fs::is_empty(root)) << "a temp dir or half an asset is left";

  // With room again, the same upload goes through.
  stored = assets.store(triangle_upload(256 << 10), "alice");
  ASSERT_TRUE(std::holds_alternative<StoredAsset>(stored)) << std::get<Problem>(stored).detail;
  EXPECT_TRUE(std::get<StoredAsset>(stored).created);
  EXPECT_TRUE(assets.main_file(std::get<StoredAsset>(stored).info.id, "gltf"));
}

}  // namespace
}  // namespace tessera::server
