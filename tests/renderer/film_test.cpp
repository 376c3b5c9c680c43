#include <gtest/gtest.h>

#include <random>
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

TEST(Film, StateRoundTripsExactlyAndRefusesAnotherSize) {
  Film film(5, 3);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 1e6f);
  for (int s = 0; s < 9; ++s)
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 5; ++x) film.add_sample(x, y, Rgb(u(rng), u(rng) * 1e-6f, u(rng) * 1e3f));
  std::string bytes = "prefix";
  film.append_state(bytes);
  ASSERT_EQ(bytes.size(), 6 + Film::state_size(5, 3));
  EXPECT_EQ(Film::state_size(5, 3), 15u * (3 * 16 + 4));
  const std::string_view state = std::string_view(bytes).substr(6);

  Film copy(5, 3);
  ASSERT_TRUE(copy.read_state(state));
  EXPECT_TRUE(copy.sums() == film.sums());
  EXPECT_TRUE(copy.sums_lum2() == film.sums_lum2());

  Film smaller(4, 3);
  EXPECT_FALSE(smaller.read_state(state));
  EXPECT_FALSE(copy.read_state(state.substr(1)));
  EXPECT_TRUE(copy.sums() == film.sums());  // unchanged by the refused read
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
