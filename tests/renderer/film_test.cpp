#include <gtest/gtest.h>

#include <random>

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

}  // namespace
}  // namespace tessera
