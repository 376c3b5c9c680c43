// The one rule for files an asset names from inside it (proto/asset_path.h): glTF URIs decoded and normalised,
// paths confined to the asset's folder, symbolic links included.
#include "proto/asset_path.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>

namespace tessera::proto {
namespace {

TEST(AssetPath, UrisAreDecodedAndNormalised) {
  const std::pair<const char*, const char*> cases[] = {
      {"Normal%20Map.png", "Normal Map.png"},
      {"./mesh.bin", "mesh.bin"},
      {"textures/wood.png", "textures/wood.png"},
      {"./a/./b//c.png", "a/b/c.png"},
      {"100%25.png", "100%.png"},
      {"t%C3%A9.png", "t\xc3\xa9.png"},
      {"a+b.png", "a+b.png"},  // '+' is a plus in a path, not a space
  };
  for (const auto& [uri, path] : cases) {
    const AssetPath p = asset_path_from_uri(uri);
    EXPECT_EQ(p.problem, "") << uri;
    EXPECT_EQ(p.path, path) << uri;
    // Encoded again, it decodes to the same path.
    EXPECT_EQ(asset_path_from_uri(uri_from_asset_path(p.path)).path, path) << uri;
  }
}

TEST(AssetPath, WhatLeavesTheAssetIsRefused) {
  const std::pair<const char*, const char*> cases[] = {
      {"../x.bin", "\"..\""},
      {"a/../../x.bin", "\"..\""},
      {"%2e%2e/x.bin", "\"..\""},
      {"a%2F..%2F..%2Fx", "\"..\""},
      {"/etc/passwd", "absolute"},
      {"%2Fetc/passwd", "absolute"},
      {"http://h/x.bin", "scheme"},
      {"file:///etc/passwd", "scheme"},
      {"C:\\x.bin", "drive"},
      {"sub\\x.bin", "backslash"},
      {"C:/x.bin", "scheme"},
      {".asset.json", "dot"},
      {"x%zz.bin", "percent"},
      {"x%2", "percent"},
      {"x.bin?v=1", "query"},
      {"x.bin#f", "query"},
      {"", "empty"},
      {"x%00.bin", "control"},
      {"./", "folder"},
      {"a/", "folder"},
  };
  for (const auto& [uri, why] : cases) {
    const AssetPath p = asset_path_from_uri(uri);
    EXPECT_EQ(p.path, "") << uri;
    EXPECT_NE(p.problem.find(why), std::string::npos) << uri << ": " << p.problem;
  }
  EXPECT_TRUE(is_data_uri("data:application/octet-stream;base64,AAAA"));
  EXPECT_TRUE(is_data_uri("DATA:image/png;base64,AAAA"));
  EXPECT_FALSE(is_data_uri("data.bin"));
  // Paths (a JSON scene's file names) are not decoded: "%20" stays.
  EXPECT_EQ(asset_path("a%20b.png").path, "a%20b.png");
}

TEST(AssetPath, FilesAreConfinedToTheFolderThroughLinks) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("tessera-asset-path-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "asset" / "sub");
  std::ofstream(dir / "asset" / "sub" / "in.png") << "x";
  std::ofstream(dir / "secret.txt") << "x";
  fs::create_symlink(dir / "secret.txt", dir / "asset" / "out.png");
  fs::create_symlink(dir / "asset" / "sub" / "in.png", dir / "asset" / "alias.png");
  fs::create_symlink(dir, dir / "asset" / "up");
  bool outside = true;
  EXPECT_EQ(confined_file(dir / "asset", "sub/in.png", &outside), fs::canonical(dir / "asset" / "sub" / "in.png"));
  EXPECT_FALSE(outside);
  EXPECT_TRUE(confined_file(dir / "asset", "alias.png"));  // a link that stays inside
  EXPECT_FALSE(confined_file(dir / "asset", "out.png", &outside));
  EXPECT_TRUE(outside);
  EXPECT_FALSE(confined_file(dir / "asset", "up/secret.txt", &outside));
  EXPECT_TRUE(outside);
  EXPECT_FALSE(confined_file(dir / "asset", "missing.png", &outside));
  EXPECT_FALSE(outside);
  EXPECT_FALSE(confined_file(dir / "asset", "sub", &outside));  // a folder is not a file
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tessera::proto
