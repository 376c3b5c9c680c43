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

}  // namespace
}  // namespace tessera
