// Checkpoints: what the scheduler writes after a pass reads back bit for bit, and anything else (another render's
// settings or size, a torn or corrupted file, another format) is refused rather than resumed from.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>

#include "renderer/film_codec.h"
#include "server/jobs/checkpoint.h"

namespace tessera::server {
namespace {

Film noisy_film(int width, int height, uint32_t samples) {
  Film film(width, height);
  std::mt19937_64 rng(11);
  std::exponential_distribution<float> e(0.5f);
  for (uint32_t s = 0; s < samples; ++s)
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) film.add_sample(x, y, Rgb(e(rng), e(rng), e(rng)));
  film.set_samples(samples);
  return film;
}

TEST(Checkpoint, RoundTripsExactly) {
  const Film film = noisy_film(7, 5, 13);
  const std::string bytes = encode_checkpoint(film, 4, 2.5, 0x1234);
  const std::optional<Checkpoint> c = decode_checkpoint(bytes, 7, 5, 0x1234);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->passes, 4u);
  EXPECT_EQ(c->elapsed_s, 2.5);
  EXPECT_EQ(c->film.samples(), 13u);
  EXPECT_TRUE(c->film.sums() == film.sums());
  EXPECT_TRUE(c->film.sums_lum2() == film.sums_lum2());
  EXPECT_EQ(encode_checkpoint(c->film, c->passes, c->elapsed_s, 0x1234), bytes);
}

TEST(Checkpoint, RefusesAnotherRenderAndDamagedBytes) {
  const std::string bytes = encode_checkpoint(noisy_film(7, 5, 3), 2, 1.0, 99);
  ASSERT_TRUE(decode_checkpoint(bytes, 7, 5, 99));
  EXPECT_FALSE(decode_checkpoint(bytes, 7, 5, 98)) << "other render settings";
  EXPECT_FALSE(decode_checkpoint(bytes, 5, 7, 99)) << "another image size";
  EXPECT_FALSE(decode_checkpoint(bytes.substr(0, bytes.size() - 1), 7, 5, 99)) << "torn write";
  EXPECT_FALSE(decode_checkpoint(bytes + '\0', 7, 5, 99)) << "trailing bytes";
  EXPECT_FALSE(decode_checkpoint(bytes.substr(0, 20), 7, 5, 99)) << "header only";
  EXPECT_FALSE(decode_checkpoint("", 7, 5, 99));
  // The magic, the version, the sample count, the elapsed time, the payload's middle and its last byte.
  for (size_t at : {size_t{0}, size_t{8}, size_t{20}, size_t{32}, bytes.size() / 2, bytes.size() - 1}) {
    std::string damaged = bytes;
    damaged[at] = static_cast<char>(damaged[at] ^ 0x10);
    EXPECT_FALSE(decode_checkpoint(damaged, 7, 5, 99)) << "a bit flipped at byte " << at;
  }
}

std::string read_fixture(const std::string& name) {
  std::ifstream in("tests/renderer/fixtures/" + name, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Checkpoints of the formats before the film codec ("TSRCKPT1" version 2, the checksum over the payload only, and 3,
// over the header too; tests/renderer/fixtures, written by that encoder) still resume, so an upgrade does not restart
// the jobs it interrupted.
TEST(Checkpoint, ReadsTheFormatsBeforeTheFilmCodec) {
  Film film(3, 2);
  for (uint32_t s = 0; s < 5; ++s)
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < 3; ++x)
        film.add_sample(x, y, Rgb(0.25f * (s + 1) + x, 1.5f * y + 0.125f * s, s == 2 ? -1.0f : 3.0f + x * y + s));
  for (const char* name : {"checkpoint-v2.ckpt", "checkpoint-v3.ckpt"}) {
    const std::string bytes = read_fixture(name);
    const std::optional<Checkpoint> c = decode_checkpoint(bytes, 3, 2, 0x1234abcd5678ef00ull);
    ASSERT_TRUE(c) << name;
    EXPECT_EQ(c->film.samples(), 5u);
    EXPECT_EQ(c->film.pixel_samples(2, 1), 5u);
    EXPECT_EQ(c->passes, 3u);
    EXPECT_EQ(c->elapsed_s, 1.25);
    EXPECT_TRUE(c->film.sums() == film.sums());
    EXPECT_TRUE(c->film.sums_lum2() == film.sums_lum2());
    EXPECT_FALSE(decode_checkpoint(bytes, 3, 2, 0x1234abcd5678ef01ull)) << name << ": other render settings";
    EXPECT_FALSE(decode_checkpoint(bytes, 2, 3, 0x1234abcd5678ef00ull)) << name << ": another size";
  }
}

// A checkpoint records its sample range and its job's budget (a work unit's, of the whole job's), and every layer.
TEST(Checkpoint, RecordsTheSampleRangeTheBudgetAndEveryLayer) {
  Film film = noisy_film(4, 3, 6);
  const int depth = film.add_layer("depth", 1, LayerKind::kDistance);
  const float d = 2.5f, escaped = INFINITY;
  film.add_layer_sample(depth, 1, 1, &d);
  film.add_layer_sample(depth, 1, 1, &escaped);
  RenderSettings unit;
  unit.width = 4;
  unit.height = 3;
  unit.first_sample = 10;
  unit.spp = 6;
  unit.job_spp = 40;
  const std::string bytes = encode_checkpoint(film, 2, 0.5, 77, unit);
  const std::optional<FilmFile> f = decode_film_file(bytes);
  ASSERT_TRUE(f);
  EXPECT_EQ(f->first_sample, 10u);
  EXPECT_EQ(f->sample_count, 6u);
  EXPECT_EQ(f->job_spp, 40u);
  EXPECT_EQ(f->fingerprint, 77u);
  const std::optional<Checkpoint> c = decode_checkpoint(bytes, 4, 3, 77);
  ASSERT_TRUE(c);
  ASSERT_EQ(c->film.layer("depth"), depth);
  EXPECT_EQ(c->film.layer_at(depth).hits, film.layer_at(depth).hits);
  EXPECT_TRUE(c->film.layer_at(depth).sums == film.layer_at(depth).sums);
  unit.job_spp = 0;
  unit.first_sample = 0;
  EXPECT_EQ(decode_film_file(encode_checkpoint(film, 2, 0.5, 77, unit))->job_spp, 6u) << "a whole job's budget";
}

}  // namespace
}  // namespace tessera::server
