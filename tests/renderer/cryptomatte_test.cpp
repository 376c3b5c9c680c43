// Cryptomatte (cryptomatte.h, the crypto_object and crypto_material passes): ids as the specification makes them,
// counts that merge to the same bits in any order, coverage that is each object's share of a pixel's samples, and an
// EXR with the specification's channels and manifests.
#include <gtest/gtest.h>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <map>
#include <random>
#include <set>

#include "renderer/aov.h"
#include "renderer/cryptomatte.h"
#include "renderer/job.h"
#include "renderer/output.h"
#include "renderer/render_settings.h"
#include "renderer/scene.h"
#include "renderer/scene_error.h"
#include "renderer/session.h"
#include "tests/renderer/pass_test_util.h"

namespace tessera {
namespace {

using nlohmann::json;

uint32_t bits_of(float f) {
  uint32_t b;
  std::memcpy(&b, &f, sizeof b);
  return b;
}

TEST(Cryptomatte, IdsAreTheSpecificationsHashes) {
  // The manifest of the specification's example (Cryptomatte specification 1.1.0, "Manifest").
  EXPECT_EQ(cryptomatte::id_of("bunny"), 0x13851a76u);
  EXPECT_EQ(cryptomatte::id_of("default"), 0x42c9679fu);
  EXPECT_EQ(cryptomatte::id_of("bunny_porcelain_mat"), 0xb24b26d4u);
  // The exponent is clamped to [1, 254]: no zero, denormal, infinity or NaN; sign and mantissa kept.
  EXPECT_EQ(cryptomatte::id_bits(0x00000000u), 0x00800000u);
  EXPECT_EQ(cryptomatte::id_bits(0x807fffffu), 0x80ffffffu);
  EXPECT_EQ(cryptomatte::id_bits(0x7f800001u), 0x7f000001u);
  EXPECT_EQ(cryptomatte::id_bits(0xff812345u), 0xff012345u);
  for (uint32_t h : {0u, 0x7f800000u, 0xffffffffu, 0x00012345u}) {
    const float f = cryptomatte::id_float(cryptomatte::id_bits(h));
    EXPECT_TRUE(std::isnormal(f)) << std::hex << h;
  }
  const auto meta = cryptomatte::exr_metadata("CryptoObject", {{"bunny", 0x13851a76u}, {"default", 0x42c9679fu}});
  ASSERT_EQ(meta.size(), 4u);
  // The key: the first 7 hexadecimal digits of MurmurHash3("CryptoObject") = 3ae39a58.
  EXPECT_EQ(meta[0], (std::pair<std::string, std::string>{"cryptomatte/3ae39a5/name", "CryptoObject"}));
  EXPECT_EQ(meta[1].second, "MurmurHash3_32");
  EXPECT_EQ(meta[2].second, "uint32_to_float32");
  EXPECT_EQ(json::parse(meta[3].second), (json{{"bunny", "13851a76"}, {"default", "42c9679f"}}));
  EXPECT_EQ(cryptomatte::channel_names("CryptoMaterial", 6),
            (std::vector<std::string>{"CryptoMaterial00.R", "CryptoMaterial00.G", "CryptoMaterial00.B",
                                      "CryptoMaterial00.A", "CryptoMaterial01.R", "CryptoMaterial01.G",
                                      "CryptoMaterial01.B", "CryptoMaterial01.A", "CryptoMaterial02.R",
                                      "CryptoMaterial02.G", "CryptoMaterial02.B", "CryptoMaterial02.A"}));
}

// An asset's names are not bounded: an id is made of the name's first 256 bytes, cut before a UTF-8 continuation
// byte, and the manifest names it so.
TEST(Cryptomatte, LongNamesAreCutToTheirFirst256Bytes) {
  const std::string long_name = std::string(255, 'a') + "\xc3\xa9" + std::string(100, 'b');  // é across byte 256
  const cryptomatte::Ids ids = cryptomatte::ids_of({long_name, "short"}, {});
  const std::string cut(255, 'a');
  EXPECT_EQ(ids.object[0], cryptomatte::id_of(cut));
  EXPECT_EQ(ids.object_manifest.count(cut), 1u);
  EXPECT_EQ(ids.object[1], cryptomatte::id_of("short"));
}

// A film of one id layer, `samples` samples of random ids from `ids` in each of its pixels.
Film random_id_film(uint32_t seed, uint32_t samples, uint32_t ids) {
  Film film(5, 4);
  const int layer = film.add_layer("crypto_object", 12, LayerKind::kIds);
  std::mt19937 rng(seed);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 5; ++x)
      for (uint32_t s = 0; s < samples; ++s) film.add_id_sample(layer, x, y, 1000 + rng() % ids);
  film.set_samples(samples);
  return film;
}

TEST(Cryptomatte, CountsMergeToTheSameBitsInAnyOrderAndRankByCoverage) {
  // Up to 16 ids a pixel (Film::kMaxIdsPerPixel): counts are kept exactly, so any order of merging gives one film.
  const Film a = random_id_film(1, 7, 9), b = random_id_film(2, 3, 9), c = random_id_film(3, 11, 9);
  Film abc = a, cba = c, bac = b;
  abc.merge(b);
  abc.merge(c);
  cba.merge(b);
  cba.merge(a);
  bac.merge(a);
  bac.merge(c);
  EXPECT_EQ(abc.layer_at(1).ids, cba.layer_at(1).ids);
  EXPECT_EQ(abc.layer_at(1).ids, bac.layer_at(1).ids);
  EXPECT_EQ(abc.pixel_samples(0, 0), 21u);
  for (size_t p = 0; p < 20; ++p) {
    uint32_t counted = 0;
    for (const IdCount& e : abc.layer_at(1).ids[p]) counted += e.count;
    EXPECT_EQ(counted, 21u) << p;
  }

  // Ranks: by falling count, ties to the lower id; coverage = count / samples; ranks past the pixel's ids are 0.
  Film film(1, 1);
  const int layer = film.add_layer("crypto_object", 12, LayerKind::kIds);
  for (uint32_t id : {7u, 9u, 9u, 5u, 9u, 5u, 8u, 5u})
    film.add_id_sample(layer, 0, 0, cryptomatte::id_bits(id << 23 | id));
  film.set_samples(10);  // two samples escaped: no id
  const std::vector<float> ranks = film.resolve_layer(layer);
  ASSERT_EQ(ranks.size(), 12u);
  const std::vector<std::pair<uint32_t, float>> expected = {{5, 0.3f}, {9, 0.3f}, {7, 0.1f}, {8, 0.1f}};
  for (size_t r = 0; r < 6; ++r) {
    if (r < expected.size()) {
      EXPECT_EQ(bits_of(ranks[2 * r]), cryptomatte::id_bits(expected[r].first << 23 | expected[r].first)) << r;
      EXPECT_FLOAT_EQ(ranks[2 * r + 1], expected[r].second) << r;
    } else {
      EXPECT_EQ(ranks[2 * r], 0.0f) << r;
      EXPECT_EQ(ranks[2 * r + 1], 0.0f) << r;
    }
  }
}

TEST(Cryptomatte, APixelKeepsItsSixteenIdsOfMostSamples) {
  Film film(1, 1), other(1, 1);
  const int layer = film.add_layer("crypto_object", 12, LayerKind::kIds);
  other.add_layer("crypto_object", 12, LayerKind::kIds);
  for (uint32_t id = 1; id <= 20; ++id) film.add_id_sample(layer, 0, 0, id);  // ids 17 … 20 find the pixel full
  EXPECT_EQ(film.layer_at(layer).ids[0].size(), Film::kMaxIdsPerPixel);
  EXPECT_EQ(film.layer_at(layer).ids[0].back().id, 16u);
  for (int k = 0; k < 3; ++k) other.add_id_sample(layer, 0, 0, 30);
  film.merge(other);
  // 17 ids: the one of fewest samples and highest id goes.
  ASSERT_EQ(film.layer_at(layer).ids[0].size(), Film::kMaxIdsPerPixel);
  EXPECT_EQ(film.layer_at(layer).ids[0].back(), (IdCount{30, 3}));
  EXPECT_EQ(film.layer_at(layer).ids[0][14].id, 15u);
}

using test::cornell_scene;
using test::settings;

Film render(const std::shared_ptr<const Scene>& scene, const RenderSettings& s, int threads = 2) {
  ThreadPool pool(threads);
  RenderSession session(scene, s, pool);
  session.run();
  return session.film();
}

class CryptomatteRender : public testing::TestWithParam<const char*> {};

// At one sample a pixel, a pixel's rank 0 is the id of the object and material its sample hit, with coverage 1, as
// the id passes (the pixel's sample 0, numbered apart from the names) say.
TEST_P(CryptomatteRender, AtOneSampleRankZeroIsWhatTheSampleHit) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  const std::vector<std::string> objects = scene->object_names();
  const RenderSettings s =
      settings(24, 24, 1, GetParam(), {"object_id", "material_id", "crypto_object", "crypto_material"});
  const Image image = resolve_image(render(scene, s), s.aovs);
  std::map<std::string, const ImageLayer*> layers;
  for (const ImageLayer& l : image.layers) layers[l.name] = &l;
  size_t hits = 0;
  for (size_t p = 0; p < 24 * 24; ++p) {
    const float object = layers.at("object_id")->pixels[p], material = layers.at("material_id")->pixels[p];
    const float* co = &layers.at("crypto_object")->pixels[12 * p];
    const float* cm = &layers.at("crypto_material")->pixels[12 * p];
    if (object == 0) {
      EXPECT_EQ(co[1], 0.0f) << p;
      continue;
    }
    ++hits;
    const auto o = static_cast<size_t>(object) - 1, m = static_cast<size_t>(material) - 1;
    EXPECT_EQ(bits_of(co[0]), cryptomatte::id_of(objects.at(o))) << p;
    EXPECT_EQ(co[1], 1.0f) << p;
    EXPECT_EQ(bits_of(cm[0]), cryptomatte::id_of(scene->material_names.at(m))) << p;
    EXPECT_EQ(cm[1], 1.0f) << p;
    for (int r = 2; r < 12; ++r) EXPECT_EQ(co[r], 0.0f) << p;
  }
  EXPECT_GT(hits, 500u);
}

// Over many samples, the coverage an object has summed over the image is its share of the samples, counted from the
// same samples rendered one at a time (the job split into units of one sample, each unit's rank 0 being what its
// sample hit); merged in any order, the units are the whole render's film.
TEST_P(CryptomatteRender, CoverageSumsToEachObjectsShareOfSamples) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  constexpr uint32_t kSpp = 12;
  constexpr int kSide = 20;
  const RenderSettings whole = settings(kSide, kSide, kSpp, GetParam(), {"crypto_object"});
  const Film film = render(scene, whole);

  std::vector<Film> units;
  std::map<uint32_t, uint64_t> samples_of;  // id → samples that hit it
  for (uint32_t k = 0; k < kSpp; ++k) {
    RenderSettings unit = whole;
    unit.first_sample = k;
    unit.spp = 1;
    unit.job_spp = kSpp;
    units.push_back(render(scene, unit, 1));
    const std::vector<float> ranks = units.back().resolve_layer("crypto_object");
    for (size_t p = 0; p < kSide * kSide; ++p)
      if (ranks[12 * p + 1] == 1.0f) ++samples_of[bits_of(ranks[12 * p])];
  }
  ASSERT_GE(samples_of.size(), 6u) << "the walls, the boxes and the light";

  std::map<uint32_t, double> coverage_of;
  const std::vector<float> ranks = film.resolve_layer("crypto_object");
  size_t fits = 0;
  for (size_t p = 0; p < kSide * kSide; ++p) {
    fits += film.layer_at(1).ids[p].size() <= static_cast<size_t>(cryptomatte::kRanks);
    for (int r = 0; r < cryptomatte::kRanks; ++r)
      if (ranks[12 * p + 2 * r + 1] > 0) coverage_of[bits_of(ranks[12 * p + 2 * r])] += ranks[12 * p + 2 * r + 1];
  }
  ASSERT_EQ(fits, static_cast<size_t>(kSide * kSide)) << "every pixel's objects fit in the ranks";
  ASSERT_EQ(coverage_of.size(), samples_of.size());
  for (const auto& [id, samples] : samples_of)
    EXPECT_NEAR(coverage_of.at(id) * kSpp, static_cast<double>(samples), 1e-3) << std::hex << id;

  Film forward = units.front(), backward = units.back();
  for (size_t k = 1; k < units.size(); ++k) forward.merge(units[k]);
  for (size_t k = units.size() - 1; k-- > 0;) backward.merge(units[k]);
  EXPECT_EQ(forward.layer_at(1).ids, film.layer_at(1).ids);
  EXPECT_EQ(backward.layer_at(1).ids, film.layer_at(1).ids);
}

INSTANTIATE_TEST_SUITE_P(Integrators, CryptomatteRender, testing::Values("path", "bdpt"));

TEST(CryptomatteImage, TheExrHoldsTheSpecificationsChannelsFloatAndManifests) {
  json doc = cornell_scene();
  doc["objects"][6]["name"] = "tall box";
  auto scene = load_scene(doc, "/scene", SceneLoadOptions{});
  RenderSettings s = settings(16, 16, 4, "path", {"albedo", "crypto_object", "crypto_material"});
  s.exr_half = true;
  OutputPipeline pipeline(s, OutputSpec{false, true});
  std::string exr;
  pipeline.run(render(scene, s), [&](ImageFormat, std::string_view bytes) { exr = bytes; });

  std::vector<unsigned char> buffer(exr.begin(), exr.end());
  OIIO::Filesystem::IOMemReader reader(buffer.data(), buffer.size());
  auto in = OIIO::ImageInput::open("result.exr", nullptr, &reader);
  ASSERT_TRUE(in) << OIIO::geterror();
  const OIIO::ImageSpec& spec = in->spec();
  std::vector<std::string> crypto;
  for (int c = 0; c < spec.nchannels; ++c) {
    const std::string& name = spec.channelnames[static_cast<size_t>(c)];
    if (name.rfind("Crypto", 0) != 0) continue;
    crypto.push_back(name);
    EXPECT_EQ(spec.channelformat(c), OIIO::TypeDesc::FLOAT) << name << ": ids are 32-bit floats whatever the EXR";
  }
  std::vector<std::string> expected = cryptomatte::channel_names("CryptoObject", 6);
  for (const std::string& c : cryptomatte::channel_names("CryptoMaterial", 6)) expected.push_back(c);
  std::sort(crypto.begin(), crypto.end());
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(crypto, expected);
  const int albedo = spec.channelindex("albedo.R");
  ASSERT_GE(albedo, 0);
  EXPECT_EQ(spec.channelformat(albedo), OIIO::TypeDesc::HALF) << "albedo keeps the job's precision";

  EXPECT_EQ(spec.get_string_attribute("cryptomatte/3ae39a5/name"), "CryptoObject");
  EXPECT_EQ(spec.get_string_attribute("cryptomatte/3ae39a5/hash"), "MurmurHash3_32");
  EXPECT_EQ(spec.get_string_attribute("cryptomatte/3ae39a5/conversion"), "uint32_to_float32");
  const json objects = json::parse(spec.get_string_attribute("cryptomatte/3ae39a5/manifest"));
  EXPECT_EQ(objects.size(), scene->object_names().size());
  for (const std::string& name : scene->object_names()) {
    char hex[9];
    std::snprintf(hex, sizeof hex, "%08x", cryptomatte::id_of(name));
    EXPECT_EQ(objects.value(name, ""), hex) << name;
  }
  EXPECT_TRUE(objects.contains("tall box"));
  EXPECT_TRUE(objects.contains("objects[0]"));
  const json materials = json::parse(spec.get_string_attribute("cryptomatte/be359d6/manifest"));
  for (const char* m : {"white", "red", "green", "light"}) EXPECT_TRUE(materials.contains(m)) << m;
}

// A glTF asset's objects go by their node's name, else their mesh's (the Duck's one node is unnamed; its mesh is
// LOD3spShape), and its materials by theirs.
TEST(CryptomatteNames, AGltfObjectIsNamedByItsNodeOrMesh) {
  SceneLoadOptions options;
  options.asset_root = "examples/duck";
  auto scene = load_scene(json{{"gltf", "Duck.glb"}}, "/scene", options);
  EXPECT_EQ(scene->object_names(), std::vector<std::string>{"LOD3spShape"});
  EXPECT_EQ(scene->material_names, std::vector<std::string>{"blinn3-fx"});
}

TEST(CryptomatteImage, ThePassesLookShowsEachIdsColourByCoverage) {
  auto scene = load_scene(cornell_scene(), "/scene", SceneLoadOptions{});
  const RenderSettings s = settings(12, 12, 4, "path", {"crypto_object"});
  const Image image = resolve_image(render(scene, s), s.aovs);
  const std::vector<float> look = aov_look(*find_aov("crypto_object"), image.layers.at(1).pixels);
  ASSERT_EQ(look.size(), 12u * 12u * 3u);
  std::set<std::vector<float>> colours;
  for (size_t p = 0; p < 144; ++p) colours.insert({look[3 * p], look[3 * p + 1], look[3 * p + 2]});
  EXPECT_GE(colours.size(), 4u);
  EXPECT_FALSE(encode_pass_png(image, "crypto_object").empty());
}

TEST(CryptomatteSettings, LightTracingRefusesItAndTheFilmCountsItsBytes) {
  const RenderLimits limits;
  try {
    render_settings_from_json(json{{"integrator", "light"}, {"aovs", {"crypto_object"}}}, "/render", limits);
    ADD_FAILURE() << "accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), "/render/aovs/0");
  }
  EXPECT_EQ(film_bytes(10, 10, {"crypto_object"}) - film_bytes(10, 10, {}),
            100u * (sizeof(std::vector<IdCount>) + Film::kMaxIdsPerPixel * sizeof(IdCount) + 16));
}

}  // namespace
}  // namespace tessera
