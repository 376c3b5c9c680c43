#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <stdexcept>
#include <thread>

#include "renderer/film.h"

namespace tessera {
namespace {

TEST(Film, ResolvesTheMeanOfItsSamples) {
  Film film(4, 3);
  film.add_sample(1, 2, Rgb(1, 2, 3));
  film.add_sample(1, 2, Rgb(3, 2, 1));
  film.set_samples(2);
  Rgb p = film.pixel(1, 2);
  EXPECT_FLOAT_EQ(p.x, 2);
  EXPECT_FLOAT_EQ(p.y, 2);
  EXPECT_FLOAT_EQ(p.z, 2);
  std::vector<float> rgb = film.resolve();
  ASSERT_EQ(rgb.size(), 4u * 3u * 3u);
  EXPECT_FLOAT_EQ(rgb[(2 * 4 + 1) * 3], 2);
  EXPECT_FLOAT_EQ(rgb[0], 0);
}

TEST(Film, RelativeErrorMatchesTheSampleStatistics) {
  // Every pixel gets n samples of a grey value with mean 1 and standard deviation 0.5: the standard error of each
  // pixel mean is 0.5 / sqrt(n), so the relative error estimate is that over 1.
  const int n = 64;
  Film film(16, 16);
  std::mt19937_64 rng(3);
  std::normal_distribution<float> g(1.0f, 0.5f);
  for (int s = 0; s < n; ++s)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) film.add_sample(x, y, Rgb(g(rng)));
  film.set_samples(n);
  EXPECT_NEAR(film.relative_error(), 0.5 / std::sqrt(double(n)), 0.005);
}

// A value of sample `s` of pixel `p`, channel `c`: signed, of several magnitudes, with escapes (infinities) and a NaN
// among the distances.
float value(uint32_t s, size_t p, int c) {
  const uint64_t h = (s * 2654435761u) ^ (p * 40503u) ^ (static_cast<uint64_t>(c) * 97u);
  return (static_cast<float>(h % 2001) - 1000.0f) * (h % 3 == 0 ? 1e-3f : 7.5f);
}
float distance(uint32_t s, size_t p) {
  if ((s + p) % 4 == 0) return INFINITY;  // the ray escaped
  if ((s + p) % 9 == 0) return NAN;
  return 0.5f + static_cast<float>((s * 31 + p * 7) % 100);
}

// A film with a signed, a distance and a non-negative layer beside the beauty, samples [first, first + count) added.
Film layered_film(int w, int h, uint32_t first, uint32_t count) {
  Film film(w, h);
  EXPECT_EQ(film.add_layer("normal", 3, LayerKind::kSigned), 1);
  EXPECT_EQ(film.add_layer("depth", 1, LayerKind::kDistance), 2);
  EXPECT_EQ(film.add_layer("albedo", 3, LayerKind::kRadiance), 3);
  for (uint32_t s = first; s < first + count; ++s)
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const size_t p = static_cast<size_t>(y * w + x);
        film.add_sample(x, y, Rgb(value(s, p, 0), value(s, p, 1), value(s, p, 2)));
        const float n[3] = {value(s, p, 3), value(s, p, 4), value(s, p, 5)}, d = distance(s, p);
        film.add_layer_sample(1, x, y, n);
        film.add_layer_sample(2, x, y, &d);
        film.add_layer_sample(3, x, y, n);
      }
  film.set_samples(count);
  return film;
}

TEST(Film, LayersAreFoundByNameAndRefuseBadOnes) {
  Film film(2, 2);
  EXPECT_EQ(film.layer("radiance"), 0);
  EXPECT_EQ(film.layer_count(), 1);
  EXPECT_EQ(film.add_layer("uv", 2, LayerKind::kSigned), 1);
  EXPECT_EQ(film.layer("uv"), 1);
  EXPECT_EQ(film.layer("nothing"), -1);
  EXPECT_THROW(film.add_layer("uv", 2, LayerKind::kSigned), std::invalid_argument);
  EXPECT_THROW(film.add_layer("", 1, LayerKind::kSigned), std::invalid_argument);
  EXPECT_THROW(film.add_layer("a b", 1, LayerKind::kSigned), std::invalid_argument);
  EXPECT_THROW(film.add_layer(std::string(32, 'x'), 1, LayerKind::kSigned), std::invalid_argument);
  EXPECT_THROW(film.add_layer("wide", 17, LayerKind::kSigned), std::invalid_argument);
  EXPECT_THROW(film.add_layer("depth", 3, LayerKind::kDistance), std::invalid_argument);
  EXPECT_THROW(film.add_layer("odd", 1, static_cast<LayerKind>(7)), std::invalid_argument);
  for (int i = 2; i < Film::kMaxLayers; ++i) film.add_layer(std::to_string(i), 1, LayerKind::kRadiance);
  EXPECT_THROW(film.add_layer("one_more", 1, LayerKind::kRadiance), std::invalid_argument);
}

TEST(Film, SignedLayersKeepNegativeValues) {
  Film film(3, 1);
  const int normal = film.add_layer("normal", 3, LayerKind::kSigned);
  const int albedo = film.add_layer("albedo", 3, LayerKind::kRadiance);
  const float a[3] = {-0.5f, 1.0f, -2.0f}, b[3] = {-0.25f, -1.0f, 1e30f};
  for (int layer : {normal, albedo}) {
    film.add_layer_sample(layer, 1, 0, a);
    film.add_layer_sample(layer, 1, 0, b);
  }
  film.set_samples(2);
  const std::vector<float> n = film.resolve_layer("normal");
  ASSERT_EQ(n.size(), 9u);
  EXPECT_FLOAT_EQ(n[3], -0.375f);
  EXPECT_FLOAT_EQ(n[4], 0.0f);
  EXPECT_FLOAT_EQ(n[5], static_cast<float>((-2.0 + 0x1p80) / 2));  // clamped to 2^80, not overflowed
  EXPECT_TRUE(film.layer_at(normal).sums[3] == Film::to_fixed_signed(-0.5f) + Film::to_fixed_signed(-0.25f));
  EXPECT_TRUE(film.layer_at(normal).sums[3] < 0);
  // A non-negative layer clamps as the beauty does.
  const std::vector<float> al = film.resolve_layer(albedo);
  EXPECT_EQ(al[3], 0.0f);
  EXPECT_FLOAT_EQ(al[4], 0.5f);
  EXPECT_EQ(Film::to_fixed_signed(NAN), 0);
  EXPECT_TRUE(Film::to_fixed_signed(-INFINITY) == -Film::to_fixed_signed(INFINITY));
  EXPECT_TRUE(Film::to_fixed_signed(0.75f) == Film::to_fixed(0.75f));
}

TEST(Film, DistanceLayersCountHitsAndNeverSumAnInfinity) {
  Film film(2, 1);
  const int depth = film.add_layer("depth", 1, LayerKind::kDistance);
  for (float d : {2.0f, INFINITY, 4.0f, NAN, -1.0f}) film.add_layer_sample(depth, 0, 0, &d);
  const float escaped = INFINITY;
  film.add_layer_sample(depth, 1, 0, &escaped);
  film.set_samples(5);
  const FilmLayer& l = film.layer_at(depth);
  EXPECT_EQ(l.hits[0], 2u);
  EXPECT_EQ(l.hits[1], 0u);
  EXPECT_TRUE(l.sums[0] == Film::to_fixed(2.0f) + Film::to_fixed(4.0f));
  EXPECT_TRUE(l.sums[1] == 0);
  const std::vector<float> r = film.resolve_layer(depth);
  EXPECT_EQ(r[0], 3.0f);      // the mean over the hits
  EXPECT_EQ(r[1], INFINITY);  // nothing hit: the ray escaped
}

TEST(Film, PerPixelSampleCounts) {
  Film film(4, 3);
  film.set_samples(6);
  EXPECT_EQ(film.pixel_samples(3, 2), 6u);
  film.set_samples(5, 1, 1, 2, 1);
  EXPECT_EQ(film.samples(), 5u);
  EXPECT_EQ(film.pixel_samples(1, 1), 5u);
  EXPECT_EQ(film.pixel_samples(2, 1), 5u);
  EXPECT_EQ(film.pixel_samples(3, 1), 0u);
  EXPECT_EQ(film.pixel_samples(1, 0), 0u);
  // Pixels of different counts resolve each over its own.
  Film uneven(2, 1);
  uneven.add_sample(0, 0, Rgb(1));
  uneven.add_sample(1, 0, Rgb(1));
  uneven.add_sample(1, 0, Rgb(3));
  uneven.pixel_sample_counts() = {1, 2};
  const std::vector<float> r = uneven.resolve_layer(0);
  EXPECT_EQ(r[0], 1.0f);
  EXPECT_EQ(r[3], 2.0f);
  // Pixels that all have the film's count resolve to the bits of resolve().
  const Film f = layered_film(5, 4, 0, 3);
  EXPECT_EQ(f.resolve_layer("radiance"), f.resolve());
}

TEST(Film, MergingDisjointSampleRangesGivesTheFilmOfAllSamplesInEveryLayer) {
  const Film whole = layered_film(5, 4, 0, 7);
  Film merged = layered_film(5, 4, 4, 3);
  merged.merge(layered_film(5, 4, 0, 1));
  merged.merge(layered_film(5, 4, 1, 3));
  EXPECT_EQ(merged.samples(), 7u);
  EXPECT_EQ(merged.pixel_sample_counts(), whole.pixel_sample_counts());
  for (int i = 0; i < whole.layer_count(); ++i) {
    EXPECT_TRUE(merged.layer_at(i).sums == whole.layer_at(i).sums) << whole.layer_at(i).name;
    EXPECT_EQ(merged.layer_at(i).hits, whole.layer_at(i).hits) << whole.layer_at(i).name;
    EXPECT_EQ(merged.resolve_layer(i), whole.resolve_layer(i)) << whole.layer_at(i).name;
  }
  // The fixture has negative normals and escaped rays, so the merge was tested on them.
  bool negative = false, escaped = false;
  for (FixedSum v : whole.layer_at(1).sums) negative = negative || v < 0;
  for (uint32_t h : whole.layer_at(2).hits) escaped = escaped || h < 7;
  EXPECT_TRUE(negative && escaped);
  Film other(5, 4);
  EXPECT_THROW(other.merge(whole), std::invalid_argument) << "another set of layers";
}

TEST(Film, SharedLayerSamplesFromManyThreadsGiveTheBitsOfOneThread) {
  const int w = 3, h = 2;
  Film serial(w, h), shared(w, h);
  for (Film* f : {&serial, &shared}) {
    f->add_layer("position", 3, LayerKind::kSigned);
    f->add_layer("depth", 1, LayerKind::kDistance);
  }
  std::vector<std::pair<int, std::array<float, 3>>> samples;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> u(-1e6f, 1e6f);
  for (int i = 0; i < 4000; ++i) samples.push_back({static_cast<int>(rng() % 6), {u(rng), u(rng) * 1e-6f, u(rng)}});
  for (const auto& [p, v] : samples) {
    serial.add_layer_sample(1, p % w, p / w, v.data());
    const float d = v[0] < 0 ? INFINITY : v[0];
    serial.add_layer_sample(2, p % w, p / w, &d);
  }
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t)
    threads.emplace_back([&, t] {
      for (size_t i = 0; i < samples.size(); ++i) {
        if (static_cast<int>(i % 8) != t) continue;
        const auto& [p, v] = samples[i];
        shared.add_layer_sample_shared(1, p % w, p / w, v.data());
        const float d = v[0] < 0 ? INFINITY : v[0];
        shared.add_layer_sample_shared(2, p % w, p / w, &d);
      }
    });
  for (std::thread& t : threads) t.join();
  EXPECT_TRUE(serial.layer_at(1).sums == shared.layer_at(1).sums);
  EXPECT_TRUE(serial.layer_at(2).sums == shared.layer_at(2).sums);
  EXPECT_EQ(serial.layer_at(2).hits, shared.layer_at(2).hits);
}

TEST(Film, SplatsFromManyThreadsGiveTheBitsOfOneThread) {
  // Values large enough that the low 64-bit words overflow many times (1e6 is about 2^60 in units of 2^-40), and
  // small ones that carry nothing: the sums must not depend on the order, interleaving or thread of the splats.
  const int w = 3, h = 2;
  std::vector<std::pair<int, Rgb>> splats;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> big(1e5f, 3e6f), small(0, 1e-3f);
  for (int i = 0; i < 20000; ++i)
    splats.push_back({static_cast<int>(rng() % (w * h)), Rgb(big(rng), small(rng), i % 7 == 0 ? 1e25f : small(rng))});
  Film serial(w, h);
  for (const auto& [p, v] : splats) serial.splat(p % w, p / w, v);
  Film shared(w, h);
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t)
    threads.emplace_back([&, t] {
      // Each thread adds every 8th splat, backwards: another order and interleaving every run.
      for (size_t i = splats.size(); i-- > 0;)
        if (static_cast<int>(i % 8) == t) shared.splat(splats[i].first % w, splats[i].first / w, splats[i].second);
    });
  for (std::thread& t : threads) t.join();
  EXPECT_TRUE(serial.sums() == shared.sums());
  // And the sums are the exact integer sums.
  FixedSum expected = 0;
  for (const auto& [p, v] : splats)
    if (p == 4) expected += Film::to_fixed(v.x);
  EXPECT_TRUE(shared.sums()[3 * 4] == expected);
  EXPECT_GT(static_cast<double>(expected), 0x1p64);
  // add_sample_shared adds the same radiance sums as add_sample, and the squared luminance.
  Film a(w, h), b(w, h);
  a.add_sample(1, 1, Rgb(0.5f, 2, 7));
  b.add_sample_shared(1, 1, Rgb(0.5f, 2, 7));
  EXPECT_TRUE(a.sums() == b.sums());
  EXPECT_EQ(a.sums_lum2(), b.sums_lum2());
}

}  // namespace
}  // namespace tessera
