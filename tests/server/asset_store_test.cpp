// The asset store when the disk runs out of room while an upload is written (the file-size limit, EFBIG, stands in
// for a full disk, ENOSPC, and a quota, EDQUOT): the upload is refused with 507 and the same problem as the
// --min-free-disk check's, and leaves no file behind; with room again, the same upload is stored.
#include <gtest/gtest.h>

#include <cerrno>
#include <fstream>
#include <iterator>

#include "renderer/scene_error.h"
#include "server/base/file_io.h"
#include "server/files/assets.h"
#include "tests/renderer/gltf_fixture.h"
#include "tests/renderer/vdb_fixture.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

namespace fs = std::filesystem;

// One triangle in a .gltf with its .bin (test::triangle_gltf), the .gltf padded with `padding` bytes.
std::vector<UploadFile> triangle_upload(size_t padding) {
  std::vector<UploadFile> files;
  for (auto& [name, bytes] : test::triangle_gltf(padding)) files.push_back({name, std::move(bytes)});
  return files;
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
  DirectoryAssetStore assets(dir.path());
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

// URIs as real assets write them: percent-encoded ("%20" for a space), "./", a subfolder; the upload's files carry
// those names ("textures/tri angle.bin") and are stored in subfolders. What leaves the upload is still refused,
// naming the URI.
TEST(AssetStore, EncodedDotSlashAndSubfolderUrisNameFilesOfTheUpload) {
  test::TempDir dir;
  DirectoryAssetStore assets(dir.path());
  std::vector<UploadFile> files = triangle_upload(0);
  auto with_uri = [&](const std::string& uri, const std::string& bin_name) {
    std::vector<UploadFile> out = files;
    for (UploadFile& f : out) {
      if (f.name == "tri.bin") f.name = bin_name;
      if (f.name != "tri.gltf") continue;
      nlohmann::json doc = nlohmann::json::parse(f.bytes);
      doc["buffers"][0]["uri"] = uri;
      f.bytes = doc.dump();
    }
    return assets.store(std::move(out), "alice");
  };
  for (const auto& [uri, name] :
       std::vector<std::pair<std::string, std::string>>{{"textures/tri%20angle.bin", "textures/tri angle.bin"},
                                                        {"./textures/./tri%20angle.bin", "textures/tri angle.bin"},
                                                        {"./tri.bin", "tri.bin"}}) {
    auto stored = with_uri(uri, name);
    ASSERT_TRUE(std::holds_alternative<StoredAsset>(stored)) << uri << ": " << std::get<Problem>(stored).detail;
    const AssetInfo& info = std::get<StoredAsset>(stored).info;
    EXPECT_TRUE(fs::is_regular_file(dir.path() / "assets" / info.id / name)) << name;
    EXPECT_TRUE(assets.main_file(info.id, "gltf"));
  }
  for (const std::string uri : {"../tri.bin", "%2e%2e/tri.bin", "textures/../../tri.bin", "/tri.bin"}) {
    auto stored = with_uri(uri, "tri.bin");
    ASSERT_TRUE(std::holds_alternative<Problem>(stored)) << uri;
    const Problem& problem = std::get<Problem>(stored);
    EXPECT_EQ(problem.status, 422);
    EXPECT_NE(problem.detail.find("buffers[0].uri \"" + uri + "\" refused"), std::string::npos) << problem.detail;
  }
  // A name that is not one the asset could use.
  auto hidden = with_uri("tri.bin", "../tri.bin");
  ASSERT_TRUE(std::holds_alternative<Problem>(hidden));
  EXPECT_EQ(std::get<Problem>(hidden).status, 422);
}

// Content addressing shares bytes, never names: the same bytes uploaded by another user under another name are an
// asset of their own that lists that user's name, and the first user's asset still lists the first name. The same
// bytes under the same name are the same asset, with both owners.
TEST(AssetStore, TheSameBytesUnderAnotherNameAreAnotherAsset) {
  test::TempDir dir;
  DirectoryAssetStore assets(dir.path());
  tessera::test::GltfBuilder b;
  b.node({{"mesh", b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, -1)}}, true);
  std::ifstream in(b.write(dir.path() / "fixture", "triangle"), std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto store = [&](const std::string& name, const std::string& owner) {
    auto stored = assets.store({{name, bytes}}, owner);
    EXPECT_TRUE(std::holds_alternative<StoredAsset>(stored)) << std::get<Problem>(stored).detail;
    return std::get<StoredAsset>(stored).info;
  };
  const AssetInfo alices = store("alice.gltf", "alice");
  const AssetInfo bobs = store("bob.gltf", "bob");
  EXPECT_NE(bobs.id, alices.id);
  EXPECT_EQ(bobs.files, std::vector<std::string>{"bob.gltf"});
  EXPECT_EQ(bobs.owners, std::vector<std::string>{"bob"});
  EXPECT_EQ(assets.get(alices.id)->files, std::vector<std::string>{"alice.gltf"});
  const AssetInfo shared = store("alice.gltf", "carol");
  EXPECT_EQ(shared.id, alices.id);
  EXPECT_EQ(shared.owners, (std::vector<std::string>{"alice", "carol"}));
}

// An environment map is judged by its bytes, not its name: a glTF binary uploaded as an .hdr (or .exr) is refused.
TEST(AssetStore, AGlbNamedAsAnEnvironmentMapIsRefused) {
  test::TempDir dir;
  DirectoryAssetStore assets(dir.path());
  tessera::test::GltfBuilder b;
  b.node({{"mesh", b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, -1)}}, true);
  std::ifstream in(b.write_glb(dir.path() / "fixture", "triangle"), std::ios::binary);
  const std::string glb((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (const char* name : {"sky.hdr", "sky.exr"}) {
    auto stored = assets.store({{name, glb}}, "alice");
    ASSERT_TRUE(std::holds_alternative<Problem>(stored)) << name << " was stored";
    EXPECT_EQ(std::get<Problem>(stored).status, 422) << std::get<Problem>(stored).detail;
    EXPECT_NE(std::get<Problem>(stored).detail.find("cannot read the environment map"), std::string::npos)
        << std::get<Problem>(stored).detail;
  }
}

// An OpenVDB file is a volume asset, checked by loading its grid as a medium's: a job's reference to it at a
// medium's "grid" resolves to the file, and at any other field it is the wrong kind; a .vdb that OpenVDB cannot
// read, or that holds no float grid, is refused.
TEST(AssetStore, AVdbIsAVolumeAssetThatResolvesAtAMediumsGrid) {
  test::TempDir dir;
  DirectoryAssetStore assets(dir.path());
  const auto read = [](const fs::path& file) {
    std::ifstream in(file, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  };
  tessera::test::write_vdb(dir.path() / "smoke.vdb", {tessera::test::make_grid(4, [](int, int, int) { return 1.0f; })});
  auto stored = assets.store({{"smoke.vdb", read(dir.path() / "smoke.vdb")}}, "alice");
  ASSERT_TRUE(std::holds_alternative<StoredAsset>(stored)) << std::get<Problem>(stored).detail;
  const AssetInfo info = std::get<StoredAsset>(stored).info;
  EXPECT_EQ(info.kind, "volume");
  const auto resolve = asset_resolver(assets, "alice");
  EXPECT_EQ(resolve(info.id, "/scene/objects/0/medium/grid").filename(), "smoke.vdb");
  try {
    resolve(info.id, "/scene/gltf");
    ADD_FAILURE() << "a volume asset resolved as a glTF asset";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("is a volume asset, not a gltf asset"), std::string::npos) << e.what();
  }
  auto vectors = openvdb::Vec3SGrid::create();
  vectors->setName("velocity");
  tessera::test::write_vdb(dir.path() / "vectors.vdb", {vectors});
  const std::pair<std::string, std::string> bad[] = {
      {"not an OpenVDB file", "not a readable OpenVDB file"},
      {read(dir.path() / "vectors.vdb"), "holds no float grid"},
  };
  for (const auto& [bytes, words] : bad) {
    auto refused = assets.store({{"bad.vdb", bytes}}, "alice");
    ASSERT_TRUE(std::holds_alternative<Problem>(refused)) << words;
    EXPECT_EQ(std::get<Problem>(refused).status, 422);
    EXPECT_NE(std::get<Problem>(refused).detail.find(words), std::string::npos) << std::get<Problem>(refused).detail;
  }
}

}  // namespace
}  // namespace tessera::server
