// The film codec: films of every layer kind read back bit for bit, the files of the earlier formats still read, and
// anything malformed is refused with a reason rather than read.
#include "renderer/film_codec.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "renderer/byte_fields.h"

namespace tessera {
namespace {

// Every layer's sums and hits, the squared-luminance sums and the per-pixel counts of `a` and `b` are equal.
void expect_same_film(const Film& a, const Film& b) {
  ASSERT_TRUE(a.same_layout(b));
  EXPECT_EQ(a.samples(), b.samples());
  EXPECT_EQ(a.pixel_sample_counts(), b.pixel_sample_counts());
  EXPECT_EQ(a.sums_lum2(), b.sums_lum2());
  for (int i = 0; i < a.layer_count(); ++i) {
    EXPECT_TRUE(a.layer_at(i).sums == b.layer_at(i).sums) << a.layer_at(i).name;
    EXPECT_EQ(a.layer_at(i).hits, b.layer_at(i).hits) << a.layer_at(i).name;
    EXPECT_EQ(a.layer_at(i).ids, b.layer_at(i).ids) << a.layer_at(i).name;
    EXPECT_EQ(a.layer_at(i).manifest, b.layer_at(i).manifest) << a.layer_at(i).name;
  }
}

FilmFile layered_file() {
  FilmFile f;
  f.width = 4;
  f.height = 3;
  f.first_sample = 8;
  f.sample_count = 5;
  f.job_spp = 32;
  f.region = {1, 0, 3, 2};
  f.exr_half = false;
  f.denoise = Denoiser::kRegression;
  f.display.exposure_ev = -1.5f;
  f.display.tonemap = ToneMap::kAces;
  f.fingerprint = 0xfeedface12345678ull;
  f.passes = 3;
  f.elapsed_s = 0.625;
  f.film = Film(4, 3);
  const int normal = f.film.add_layer("normal", 3, LayerKind::kSigned);
  const int depth = f.film.add_layer("depth", 1, LayerKind::kDistance);
  const int uv = f.film.add_layer("uv", 2, LayerKind::kSigned);
  for (uint32_t s = 0; s < 5; ++s)
    for (int y = 0; y < 2; ++y)
      for (int x = 1; x < 4; ++x) {
        f.film.add_sample(x, y, Rgb(0.5f * s, 1e7f * x, 3.0f));
        const float n[3] = {-0.5f * x, 0.25f * y - 1, 1e-3f * s}, d = (s + x) % 3 ? 1.5f * s : INFINITY;
        f.film.add_layer_sample(normal, x, y, n);
        f.film.add_layer_sample(depth, x, y, &d);
        f.film.add_layer_sample(uv, x, y, n);
      }
  f.film.set_samples(5, 1, 0, 3, 2);
  return f;
}

TEST(FilmCodec, RoundTripsEveryLayerBitExactly) {
  const FilmFile f = layered_file();
  const std::string bytes = encode_film_file(f);
  std::string why;
  const std::optional<FilmFile> d = decode_film_file(bytes, &why);
  ASSERT_TRUE(d) << why;
  EXPECT_EQ(d->width, 4);
  EXPECT_EQ(d->height, 3);
  EXPECT_EQ(d->first_sample, 8u);
  EXPECT_EQ(d->sample_count, 5u);
  EXPECT_EQ(d->job_spp, 32u);
  EXPECT_EQ(d->region, f.region);
  EXPECT_FALSE(d->exr_half);
  EXPECT_EQ(d->denoise, Denoiser::kRegression);
  EXPECT_EQ(d->display, f.display);
  EXPECT_EQ(d->fingerprint, f.fingerprint);
  EXPECT_EQ(d->passes, 3u);
  EXPECT_EQ(d->elapsed_s, 0.625);
  expect_same_film(d->film, f.film);
  EXPECT_EQ(d->film.layer_at(1).name, "normal");
  EXPECT_EQ(d->film.layer_at(2).kind, LayerKind::kDistance);
  EXPECT_EQ(d->film.pixel_samples(0, 0), 0u);
  EXPECT_EQ(d->film.pixel_samples(1, 0), 5u);
  EXPECT_EQ(encode_film_file(*d), bytes);
  EXPECT_EQ(bytes.size(), 96 + 4 * 40 + 12 * (16 * (3 + 3 + 1 + 2) + 4 + 4 + 4));
}

// layered_file with an id layer (Cryptomatte's) after the others: pixels with 0, 1 and 2 ids, and a manifest.
FilmFile ids_file() {
  FilmFile f = layered_file();
  const int ids = f.film.add_layer("crypto_object", 12, LayerKind::kIds);
  for (uint32_t s = 0; s < 5; ++s)
    for (int x = 2; x < 4; ++x) f.film.add_id_sample(ids, x, 1, x == 3 && s % 2 ? 0x4b0c1a2du : 0x3f8e2f10u);
  f.film.layer_at(ids).manifest = {{"floor", 0x3f8e2f10u}, {"ball", 0x4b0c1a2du}, {"unseen", 0x12345678u}};
  return f;
}

TEST(FilmCodec, RoundTripsIdLayersAndKeepsTheOtherFormatWithoutThem) {
  const FilmFile f = ids_file();
  const std::string bytes = encode_film_file(f);
  EXPECT_EQ(get_field<uint32_t>(bytes, 8), 4u) << "a film with an id layer is version 4";
  EXPECT_EQ(get_field<uint32_t>(encode_film_file(layered_file()), 8), 3u) << "and one without stays version 3";
  std::string why;
  const std::optional<FilmFile> d = decode_film_file(bytes, &why);
  ASSERT_TRUE(d) << why;
  expect_same_film(d->film, f.film);
  const FilmLayer& ids = d->film.layer_at(4);
  EXPECT_EQ(ids.kind, LayerKind::kIds);
  EXPECT_EQ(ids.ids[4 + 3], (std::vector<IdCount>{{0x3f8e2f10u, 3}, {0x4b0c1a2du, 2}}));
  EXPECT_EQ(ids.ids[4 + 2], (std::vector<IdCount>{{0x3f8e2f10u, 5}}));
  EXPECT_EQ(ids.manifest.at("ball"), 0x4b0c1a2du);
  EXPECT_EQ(encode_film_file(*d), bytes);
  // The id layer's part: 12 entry counts, 3 pairs, the manifest's count and 3 names (id, length, bytes).
  EXPECT_EQ(bytes.size(), encode_film_file(layered_file()).size() + 40 + 12 * 4 + 3 * 8 + 4 + (3 * 8 + 5 + 4 + 6));
}

std::string read_fixture(const std::string& name) {
  std::ifstream in("tests/renderer/fixtures/" + name, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The film the fixtures hold (written by the encoders of the formats before this codec).
Film fixture_film() {
  Film film(3, 2);
  for (uint32_t s = 0; s < 5; ++s)
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < 3; ++x)
        film.add_sample(x, y, Rgb(0.25f * (s + 1) + x, 1.5f * y + 0.125f * s, s == 2 ? -1.0f : 3.0f + x * y + s));
  film.set_samples(5);
  return film;
}

TEST(FilmCodec, ReadsTheEarlierFormats) {
  const Film expected = fixture_film();
  for (const char* name : {"checkpoint-v2.ckpt", "checkpoint-v3.ckpt"}) {
    std::string why;
    const std::optional<FilmFile> f = decode_film_file(read_fixture(name), &why);
    ASSERT_TRUE(f) << name << ": " << why;
    expect_same_film(f->film, expected);
    EXPECT_EQ(f->fingerprint, 0x1234abcd5678ef00ull) << name;
    EXPECT_EQ(f->passes, 3u) << name;
    EXPECT_EQ(f->elapsed_s, 1.25) << name;
    EXPECT_EQ(f->sample_count, 5u) << name;
    EXPECT_EQ(f->job_spp, 0u) << name;
    EXPECT_EQ(f->region, (PixelRegion{0, 0, 3, 2})) << name;
    // Written again in today's format, it reads back the same.
    const std::optional<FilmFile> again = decode_film_file(encode_film_file(*f));
    ASSERT_TRUE(again);
    expect_same_film(again->film, expected);
  }
  for (const char* name : {"film-v1.tfilm", "film-v2.tfilm"}) {
    std::string why;
    const std::optional<FilmFile> f = decode_film_file(read_fixture(name), &why);
    ASSERT_TRUE(f) << name << ": " << why;
    expect_same_film(f->film, expected);
    EXPECT_EQ(f->first_sample, 2u) << name;
    EXPECT_EQ(f->sample_count, 5u) << name;
    EXPECT_EQ(f->job_spp, std::string(name) == "film-v2.tfilm" ? 16u : 0u) << name;
    EXPECT_EQ(f->fingerprint, 0x0123456789abcdefull) << name;
    EXPECT_FALSE(f->exr_half) << name;
    EXPECT_EQ(f->display.exposure_ev, 0.5f) << name;
    EXPECT_EQ(f->display.tonemap, ToneMap::kAces) << name;
  }
}

// `bytes` with the field of type T at `offset` set to `v`, and the checksum made right again: a header that is
// intact but says something impossible.
template <typename T>
std::string with_field(std::string bytes, size_t offset, T v) {
  std::memcpy(bytes.data() + offset, &v, sizeof v);
  const std::string_view b = bytes;
  const uint64_t checksum = fnv1a64(b.substr(96), fnv1a64(b.substr(0, 88)));
  std::memcpy(bytes.data() + 88, &checksum, sizeof checksum);
  return bytes;
}

TEST(FilmCodec, RefusesMalformedFiles) {
  const std::string good = encode_film_file(layered_file());
  ASSERT_TRUE(decode_film_file(good));
  struct Case {
    const char* what;
    std::string bytes;
  };
  std::string dup_name = good;
  std::memcpy(dup_name.data() + 96 + 2 * 40, "normal\0", 7);  // the depth layer renamed "normal"
  std::string unterminated = good;
  std::memset(unterminated.data() + 96 + 40, 'n', 32);
  std::string padding = good;
  padding[96 + 40 + 20] = 'x';  // a byte after the name's NUL
  const std::vector<Case> cases = {
      {"empty", ""},
      {"another format", std::string("P6\n3 2\n255\n") + std::string(18, '\0')},
      {"version 4 without id layers", with_field<uint32_t>(good, 8, 4)},
      {"version 5", with_field<uint32_t>(good, 8, 5)},
      {"header only", good.substr(0, 96)},
      {"one byte short", good.substr(0, good.size() - 1)},
      {"one byte more", good + '\0'},
      {"width 0", with_field<int32_t>(good, 12, 0)},
      {"width 65537", with_field<int32_t>(good, 12, 65537)},
      {"negative height", with_field<int32_t>(good, 16, -3)},
      {"width × height beyond the file", with_field<int32_t>(with_field<int32_t>(good, 12, 65536), 16, 65536)},
      {"sample range past 2^32", with_field<uint32_t>(good, 20, 0xfffffffeu)},
      {"samples past the budget", with_field<uint32_t>(good, 64, 12)},
      {"region past the edge", with_field<int32_t>(good, 36, 4)},
      {"region near 2^31", with_field<int32_t>(good, 28, 0x7fffffff)},
      {"empty region", with_field<int32_t>(good, 40, 0)},
      {"unknown flags", with_field<uint32_t>(good, 44, 16)},
      {"unknown denoiser", with_field<uint32_t>(good, 44, 8)},
      {"unknown tone map", with_field<uint32_t>(good, 52, 2)},
      {"NaN elapsed time", with_field<double>(good, 72, NAN)},
      {"negative elapsed time", with_field<double>(good, 72, -1)},
      {"no layers", with_field<uint32_t>(good, 80, 0)},
      {"65 layers", with_field<uint32_t>(good, 80, 65)},
      {"a layer more than the file holds", with_field<uint32_t>(good, 80, 5)},
      {"a layer less", with_field<uint32_t>(good, 80, 3)},
      {"reserved word set", with_field<uint32_t>(good, 84, 1)},
      {"17 channels", with_field<uint32_t>(good, 96 + 40 + 32, 17)},
      {"0 channels", with_field<uint32_t>(good, 96 + 40 + 32, 0)},
      {"unknown kind", with_field<uint32_t>(good, 96 + 40 + 36, 3)},
      {"a distance layer of 3 channels", with_field<uint32_t>(good, 96 + 80 + 32, 3)},
      {"the beauty of 4 channels", with_field<uint32_t>(good, 96 + 32, 4)},
      {"the beauty signed", with_field<uint32_t>(good, 96 + 36, 1)},
      {"the beauty renamed", with_field<char>(good, 96, 'R')},
      {"two layers of one name", with_field<char>(dup_name, 0, 'T')},
      {"a name without its NUL", with_field<char>(unterminated, 0, 'T')},
      {"bytes after a name's NUL", with_field<char>(padding, 0, 'T')},
  };
  for (const Case& c : cases) {
    std::string why;
    EXPECT_FALSE(decode_film_file(c.bytes, &why)) << c.what;
    EXPECT_FALSE(why.empty()) << c.what;
  }
  // Any bit flipped anywhere fails the checksum, if nothing before it.
  for (size_t at = 0; at < good.size(); at += 7) {
    std::string damaged = good;
    damaged[at] = static_cast<char>(damaged[at] ^ 0x10);
    EXPECT_FALSE(decode_film_file(damaged)) << "a bit flipped at byte " << at;
  }
}

TEST(FilmCodec, RefusesMalformedIdLayers) {
  const std::string good = encode_film_file(ids_file());
  ASSERT_TRUE(decode_film_file(good));
  // The id layer's part starts after the other layers' fixed parts: its 12 entry counts, then the pairs.
  const size_t counts = encode_film_file(layered_file()).size() + 40 - 4 * 12;
  const size_t pairs = counts + 4 * 12;
  // Pixel 6 holds 1 id, pixel 7 two (its pairs at pairs + 8 and pairs + 16).
  struct Case {
    const char* what;
    std::string bytes;
  };
  const std::vector<Case> cases = {
      {"one byte short", with_field<uint32_t>(good.substr(0, good.size() - 1), 8, 4)},
      {"more ids in a pixel than a film keeps", with_field<uint32_t>(good, counts + 4 * 6, 17)},
      {"more ids than the file holds", with_field<uint32_t>(good, counts + 4 * 6, 3)},
      {"ids out of order", with_field<uint32_t>(good, pairs + 16, 0x3f8e2f10u)},
      {"an id counted 0 times", with_field<uint32_t>(good, pairs + 4, 0)},
      {"more samples counted than the pixel has", with_field<uint32_t>(good, pairs + 4, 6)},
      {"a manifest of more names than it holds", with_field<uint32_t>(good, pairs + 24, 4)},
      {"a manifest name past the end", with_field<uint32_t>(good, pairs + 24 + 8, 1000)},
      {"an id layer in version 3", with_field<uint32_t>(good, 8, 3)},
      {"an id layer of odd channels", with_field<uint32_t>(good, 96 + 4 * 40 + 32, 11)},
  };
  for (const Case& c : cases) {
    std::string why;
    EXPECT_FALSE(decode_film_file(c.bytes, &why)) << c.what;
    EXPECT_FALSE(why.empty()) << c.what;
  }
}

TEST(FilmCodec, RefusesMalformedFilesOfTheEarlierFormats) {
  const std::string ckpt = read_fixture("checkpoint-v3.ckpt"), tfilm = read_fixture("film-v2.tfilm");
  ASSERT_TRUE(decode_film_file(ckpt));
  ASSERT_TRUE(decode_film_file(tfilm));
  auto set = [](std::string b, size_t at, uint32_t v) {
    std::memcpy(b.data() + at, &v, 4);
    return b;
  };
  EXPECT_FALSE(decode_film_file(ckpt.substr(0, ckpt.size() - 1)));
  EXPECT_FALSE(decode_film_file(ckpt + '\0'));
  EXPECT_FALSE(decode_film_file(set(ckpt, 8, 4))) << "checkpoint version 4";
  EXPECT_FALSE(decode_film_file(set(ckpt, 12, 0))) << "checkpoint width 0";
  EXPECT_FALSE(decode_film_file(set(ckpt, 12, 0x80000000u))) << "checkpoint width 2^31";
  EXPECT_FALSE(decode_film_file(set(ckpt, 20, 6))) << "checkpoint sample count outside the checksum";
  EXPECT_FALSE(decode_film_file(tfilm.substr(0, tfilm.size() - 1)));
  EXPECT_FALSE(decode_film_file(set(tfilm, 12, 65537))) << ".tfilm width";
  EXPECT_FALSE(decode_film_file(set(tfilm, 28, 0x7fffffff))) << ".tfilm region";
  EXPECT_FALSE(decode_film_file(set(tfilm, 64, 3))) << ".tfilm samples past the budget";
  EXPECT_FALSE(decode_film_file(set(tfilm, 48, 0x7fc00000u))) << ".tfilm NaN exposure (version 3 would refuse it)";
}

}  // namespace
}  // namespace tessera
