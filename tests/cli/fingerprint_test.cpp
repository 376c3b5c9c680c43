// The fingerprint `tessera merge` checks parts by (clients/cli/fingerprint.h): parts of one render agree, whatever
// their sample ranges, budgets, regions or display; a difference in the scene, an asset or a setting the film depends
// on tells them apart.
#include "clients/cli/fingerprint.h"

#include <gtest/gtest.h>

#include <fstream>

namespace tessera::cli {
namespace {

using nlohmann::json;

const json kDoc = {{"kind", "scene"},
                   {"scene", {{"gltf", "asset.glb"}}},
                   {"render", {{"spp", 12}}},
                   {"outputs", {"exr"}},
                   {"priority", 3}};

RenderSettings job_settings() {
  return render_settings_from_json(json{{"width", 40}, {"height", 32}, {"spp", 12}}, "/render", {});
}

TEST(FilmFingerprint, PartsOfOneRenderAgree) {
  const std::filesystem::path none = "/nonexistent";
  const uint64_t whole = film_fingerprint(kDoc, job_settings(), none);
  EXPECT_EQ(film_fingerprint(kDoc, job_settings(), none), whole);
  // What differs between the parts of one render, or only in how it is shown or written.
  RenderSettings part = job_settings();
  part.first_sample = 5;
  part.spp = 7;
  part.job_spp = 12;
  part.region = {0, 16, 40, 16};
  part.time_limit_s = 10;
  part.noise_target = 0.1;
  part.display.exposure_ev = 1.5f;
  part.display.tonemap = ToneMap::kAces;
  part.exr_half = false;
  part.tile_size = 16;
  EXPECT_EQ(film_fingerprint(kDoc, part, none), whole);
  // Nor do the document's render settings, outputs and priority (the settings count as read).
  json other = kDoc;
  other["render"]["spp"] = 5;
  other["outputs"] = {"png"};
  other.erase("priority");
  EXPECT_EQ(film_fingerprint(other, job_settings(), none), whole);
}

TEST(FilmFingerprint, EverySettingTheFilmDependsOnTellsPartsApart) {
  const std::filesystem::path none = "/nonexistent";
  const uint64_t whole = film_fingerprint(kDoc, job_settings(), none);
  for (const json& change : {json{{"width", 41}}, json{{"height", 33}}, json{{"seed", 7}},
                             json{{"sampler", "independent"}}, json{{"integrator", "bdpt"}},
                             json{{"estimator", "area"}}, json{{"estimator", "hemisphere"}}, json{{"max_depth", 3}}}) {
    json render = {{"width", 40}, {"height", 32}, {"spp", 12}};
    render.update(change);
    EXPECT_NE(film_fingerprint(kDoc, render_settings_from_json(render, "/render", {}), none), whole) << change.dump();
  }
  json scene = kDoc;
  scene["scene"]["gltf_variant"] = "red";
  EXPECT_NE(film_fingerprint(scene, job_settings(), none), whole);
}

TEST(FilmFingerprint, TheAssetsBytesCount) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "tessera_fingerprint_test";
  std::filesystem::create_directories(dir);
  auto with_asset = [&](const std::string& bytes) {
    std::ofstream(dir / "asset.glb", std::ios::binary) << bytes;
    return film_fingerprint(kDoc, job_settings(), dir);
  };
  EXPECT_EQ(with_asset("one"), with_asset("one"));
  EXPECT_NE(with_asset("one"), with_asset("two"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tessera::cli
