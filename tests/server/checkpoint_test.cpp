// Checkpoints: what the scheduler writes after a pass reads back bit for bit, and anything else (another render's
// settings or size, a torn or corrupted file, another format) is refused rather than resumed from.
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "server/checkpoint.h"

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

// A checkpoint of the format before the header was checksummed (version 2: the checksum covers the payload only)
// still resumes, so an upgrade does not restart the jobs it interrupted.
TEST(Checkpoint, ReadsTheVersionBeforeTheHeaderWasChecksummed) {
  const Film film = noisy_film(4, 3, 5);
  std::string bytes = encode_checkpoint(film, 3, 0.75, 7);
  const uint32_t v2 = 2;
  std::memcpy(bytes.data() + 8, &v2, sizeof v2);
  const std::string_view payload = std::string_view(bytes).substr(48 + 8);
  const uint64_t payload_checksum = fnv1a64(payload);
  std::memcpy(bytes.data() + 48, &payload_checksum, sizeof payload_checksum);
  const std::optional<Checkpoint> c = decode_checkpoint(bytes, 4, 3, 7);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->film.samples(), 5u);
  EXPECT_EQ(c->passes, 3u);
  EXPECT_TRUE(c->film.sums() == film.sums());
}

}  // namespace
}  // namespace tessera::server
