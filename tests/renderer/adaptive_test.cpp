// Per-pixel adaptive sampling (adaptive.h) on a scene whose answer is known in part: the Cornell box in a corner of
// the frame under a flat sky. The sky's pixels have no variance and stop at min_spp; the box's interior, lit by its
// small ceiling light and the sky through its open side, is noisy and gets the most samples. The image agrees with a
// uniform render within its noise, and is the same bits on any thread count, after a stop and a resume from the film
// file, and for a job split into sample-range units merged in either order.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <stdexcept>

#include "renderer/adaptive.h"
#include "renderer/film_codec.h"
#include "renderer/job.h"
#include "renderer/render_settings.h"
#include "renderer/scene.h"
#include "renderer/session.h"
#include "tests/renderer/pass_test_util.h"

namespace tessera {
namespace {

using nlohmann::json;

constexpr int kSize = 64;
constexpr uint32_t kSpp = 256, kMinSpp = 16;
constexpr double kThreshold = 0.02;

// The Cornell box seen from above and to the right under a flat sky: the box in the lower left of the frame, most of
// the image sky.
json sky_and_box_scene() {
  json scene = test::cornell_scene();
  scene["environment"] = {{"color", {0.4, 0.5, 0.7}}};
  scene["camera"] = {{"from", {0.95, 0.85, -1.3}}, {"to", {0.95, 0.85, 0}}, {"up", {0, 1, 0}}, {"fov_deg", 70}};
  return scene;
}

std::shared_ptr<const Scene> sky_and_box() {
  static const std::shared_ptr<const Scene> scene = load_scene(sky_and_box_scene(), "/scene", SceneLoadOptions{});
  return scene;
}

RenderSettings adaptive_settings(double threshold = kThreshold) {
  RenderSettings s = test::settings(kSize, kSize, kSpp, "path", {"object_id"});
  s.adaptive_threshold = threshold;
  s.min_spp = kMinSpp;
  return s;
}

struct Rendered {
  Film film;
  StopReason reason;
  RenderProgress progress;
};

Rendered render(const RenderSettings& s, int threads = 2) {
  ThreadPool pool(threads);
  RenderSession session(sky_and_box(), s, pool);
  const StopReason reason = session.run();
  return {session.take_film(), reason, session.progress()};
}

// Whether two films hold the same bits: every layer's sums, the squared-luminance sums, every count.
::testing::AssertionResult same_bits(const Film& a, const Film& b) {
  if (!a.same_layout(b)) return ::testing::AssertionFailure() << "other layouts";
  if (a.samples() != b.samples()) return ::testing::AssertionFailure() << a.samples() << " vs " << b.samples();
  if (a.pixel_sample_counts() != b.pixel_sample_counts()) return ::testing::AssertionFailure() << "pixel counts differ";
  for (int l = 0; l < a.layer_count(); ++l)
    if (a.layer_at(l).sums != b.layer_at(l).sums)
      return ::testing::AssertionFailure() << "sums of layer " << a.layer_at(l).name << " differ";
  if (std::memcmp(a.sums_lum2().data(), b.sums_lum2().data(), a.sums_lum2().size() * sizeof(float)) != 0)
    return ::testing::AssertionFailure() << "squared-luminance sums differ";
  return ::testing::AssertionSuccess();
}

// Pixels by what all their samples saw (the object_id pass is a mean over the samples): sky, where every sample of the
// pixel and its 5x5 neighbourhood escaped (beyond the spread of the box's noise), and the box's.
struct Regions {
  std::vector<size_t> sky, box;
};
Regions regions(const Film& film) {
  const std::vector<float> ids = film.resolve_layer("object_id");
  Regions r;
  for (int y = 0; y < kSize; ++y)
    for (int x = 0; x < kSize; ++x) {
      const size_t i = static_cast<size_t>(y) * kSize + static_cast<size_t>(x);
      bool sky = true;
      for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) {
          const int nx = std::clamp(x + dx, 0, kSize - 1), ny = std::clamp(y + dy, 0, kSize - 1);
          sky = sky && ids[static_cast<size_t>(ny) * kSize + static_cast<size_t>(nx)] == 0.0f;
        }
      if (sky) r.sky.push_back(i);
      if (ids[i] > 0) r.box.push_back(i);
    }
  return r;
}

// The mean luminance of the pixels `pixels` of `film`'s image and its standard error, from each pixel's own samples.
struct Estimate {
  double mean = 0, standard_error = 0;
};
Estimate region_mean(const Film& film, const std::vector<size_t>& pixels) {
  const std::vector<float> image = film.resolve();
  double sum = 0, variance = 0;
  for (size_t i : pixels) {
    const double n = film.pixel_sample_counts()[i];
    const double mean = 0.2126 * image[3 * i] + 0.7152 * image[3 * i + 1] + 0.0722 * image[3 * i + 2];
    sum += mean;
    variance += std::max(0.0, (film.sums_lum2()[i] / n - mean * mean) / (n - 1));  // of the pixel's mean
  }
  const double k = static_cast<double>(pixels.size());
  return {sum / k, std::sqrt(variance) / k};
}

TEST(AdaptiveSampling, TheSkyStopsAtMinSppAndTheBoxGetsTheMostSamples) {
  const Rendered a = render(adaptive_settings());
  const Regions r = regions(a.film);
  ASSERT_GT(r.sky.size(), 1000u);
  ASSERT_GT(r.box.size(), 400u);
  // The sample_count pass is the film's per-pixel counts.
  const std::vector<uint32_t>& counts = a.film.pixel_sample_counts();
  for (size_t i : r.sky) ASSERT_EQ(counts[i], kMinSpp) << "sky pixel " << i;
  uint64_t box_samples = 0;
  uint32_t most = 0;
  for (size_t i : r.box) {
    box_samples += counts[i];
    most = std::max(most, counts[i]);
  }
  EXPECT_EQ(most, kSpp);
  EXPECT_GT(static_cast<double>(box_samples) / static_cast<double>(r.box.size()), 4.0 * kMinSpp);
  // Every count is a decision point or spp.
  for (uint32_t n : counts) EXPECT_TRUE(n % kMinSpp == 0 && n >= kMinSpp && n <= kSpp) << n;
  // samples_done is the mean over the pixels, rounded down.
  uint64_t total = 0;
  for (uint32_t n : counts) total += n;
  EXPECT_EQ(a.progress.samples_done, static_cast<uint32_t>(total / counts.size()));
  EXPECT_LT(a.progress.samples_done, kSpp / 2);
  EXPECT_EQ(a.reason, StopReason::kSamples);  // the box's noisiest pixels reach spp
}

TEST(AdaptiveSampling, StopsTheJobWhenEveryPixelHasStopped) {
  // A threshold no pixel is above after min_spp: every pixel stops there, and the schedule ends with the pass that
  // reached it, its film complete (a unit's film has all its samples).
  ThreadPool pool(2);
  RenderSession session(sky_and_box(), adaptive_settings(1.0), pool);
  std::vector<uint32_t> passes;  // the film's samples() after each pass
  const StopReason reason =
      session.run([&](const RenderProgress&, const Film& film) { passes.push_back(film.samples()); });
  for (uint32_t n : session.film().pixel_sample_counts()) ASSERT_EQ(n, kMinSpp);
  EXPECT_EQ(reason, StopReason::kAdaptiveThreshold);
  EXPECT_STREQ(stop_reason_name(reason), "adaptive_threshold");
  EXPECT_EQ(stop_reason_from_name("adaptive_threshold"), StopReason::kAdaptiveThreshold);
  ASSERT_GE(passes.size(), 2u);
  EXPECT_EQ(passes.back(), kSpp);
  EXPECT_LT(passes[passes.size() - 2], kMinSpp);
  EXPECT_EQ(session.progress().samples_done, kMinSpp);
}

TEST(AdaptiveSampling, AgreesWithAUniformRenderOfTheSameSamplesWithinItsNoise) {
  const Rendered a = render(adaptive_settings());
  uint64_t total = 0;
  for (uint32_t n : a.film.pixel_sample_counts()) total += n;
  RenderSettings uniform = adaptive_settings(0);
  uniform.spp = static_cast<uint32_t>((total + kSize * kSize - 1) / (kSize * kSize));
  uniform.seed = 8;  // independent samples
  const Rendered u = render(uniform);
  const Regions r = regions(u.film);
  for (const auto& [name, pixels] : {std::pair{"sky", r.sky}, std::pair{"box", r.box}}) {
    const Estimate ea = region_mean(a.film, pixels), eu = region_mean(u.film, pixels);
    const double se = std::hypot(ea.standard_error, eu.standard_error);
    EXPECT_LE(std::abs(ea.mean - eu.mean), 3 * se + 1e-6 * eu.mean)
        << name << ": adaptive " << ea.mean << " ± " << ea.standard_error << ", uniform " << eu.mean << " ± "
        << eu.standard_error << " at " << uniform.spp << " spp";
  }
}

TEST(AdaptiveSampling, TheFilmIsTheSameBitsOnOneAndThreeThreads) {
  EXPECT_TRUE(same_bits(render(adaptive_settings(), 1).film, render(adaptive_settings(), 3).film));
}

TEST(AdaptiveSampling, AStopAndAResumeFromTheFilmFileBetweenDecisionPointsGiveTheSameBits) {
  const RenderSettings s = adaptive_settings();
  const Rendered whole = render(s);
  ThreadPool pool(2);
  RenderSession first(sky_and_box(), s, pool);
  const StopReason stopped = first.run([&](const RenderProgress&, const Film& film) {
    // The first pass boundary past a decision point that is not one (passes end on decision points, and grow again
    // after them).
    if (film.samples() > 2 * kMinSpp && film.samples() % kMinSpp != 0) first.stop();
  });
  ASSERT_EQ(stopped, StopReason::kStopped);
  ASSERT_NE(first.film().samples() % kMinSpp, 0u);
  // Some pixels stopped at a decision point, the others went on.
  const std::vector<uint32_t>& counts = first.film().pixel_sample_counts();
  ASSERT_NE(std::count(counts.begin(), counts.end(), first.film().samples()), 0);
  ASSERT_LT(std::count(counts.begin(), counts.end(), first.film().samples()), static_cast<long>(counts.size()));
  FilmFile file;
  file.width = file.height = kSize;
  file.sample_count = first.film().samples();
  file.region = {0, 0, kSize, kSize};
  file.passes = first.progress().pass;
  const std::string bytes = encode_film_file(file, first.film());
  std::optional<FilmFile> back = decode_film_file(bytes);
  ASSERT_TRUE(back);
  RenderSession second(sky_and_box(), s, pool);
  second.restore(std::move(back->film), back->passes, 0);
  EXPECT_EQ(second.progress().samples_done, first.progress().samples_done);
  second.run();
  EXPECT_TRUE(same_bits(second.film(), whole.film));
}

TEST(AdaptiveSampling, UnitsDecideFromTheirOwnSamplesAndMergeToTheSameBitsInEitherOrder) {
  // Two units of 128 samples of the 256-sample job: each with the threshold times sqrt(2) and min_spp 8.
  auto unit = [](uint32_t first_sample, int threads) {
    RenderSettings s = adaptive_settings();
    s.first_sample = first_sample;
    s.spp = kSpp / 2;
    s.job_spp = kSpp;
    return render(s, threads);
  };
  const AdaptiveSampling scaled([] {
    RenderSettings s = adaptive_settings();
    s.spp = kSpp / 2;
    s.job_spp = kSpp;
    return s;
  }());
  EXPECT_EQ(scaled.min_spp(), kMinSpp / 2);
  EXPECT_DOUBLE_EQ(scaled.threshold(), kThreshold * std::sqrt(2.0));
  const Rendered a = unit(0, 2), b = unit(kSpp / 2, 3);
  EXPECT_EQ(a.film.samples(), kSpp / 2);
  EXPECT_FALSE(same_bits(a.film, b.film));
  Film ab = a.film, ba = b.film;
  ab.merge(b.film);
  ba.merge(a.film);
  EXPECT_TRUE(same_bits(ab, ba));
  Film again = unit(kSpp / 2, 1).film;
  again.merge(unit(0, 1).film);
  EXPECT_TRUE(same_bits(ab, again));
  // The sky's pixels have each unit's min_spp: the job's min_spp in all.
  const Regions r = regions(ab);
  ASSERT_GT(r.sky.size(), 1000u);
  for (size_t i : r.sky) ASSERT_EQ(ab.pixel_sample_counts()[i], kMinSpp);
}

TEST(AdaptiveSampling, IsRefusedByTheIntegratorsThatSplat) {
  ThreadPool pool(1);
  for (const char* integrator : {"bdpt", "light"}) {
    RenderSettings s = adaptive_settings();
    s.integrator.name = integrator;
    s.aovs.clear();
    EXPECT_THROW(RenderSession(sky_and_box(), s, pool), std::invalid_argument) << integrator;
    s.adaptive_threshold = 0;
    EXPECT_NO_THROW(RenderSession(sky_and_box(), s, pool)) << integrator;
  }
}

TEST(AdaptiveSampling, ThePixelErrorIsTheStandardErrorOverTheSquareRootOfTheMeanBelowOne) {
  Film film(2, 1);
  // Pixel 0: luminance samples 0.1 and 0.3 (grey): mean 0.2, s² = 0.02, standard error 0.1.
  film.add_sample(0, 0, Rgb(0.1f));
  film.add_sample(0, 0, Rgb(0.3f));
  // Pixel 1: 3 and 5: mean 4, standard error 1, relative to the mean above 1.
  film.add_sample(1, 0, Rgb(3.0f));
  film.add_sample(1, 0, Rgb(5.0f));
  film.set_samples(2);
  EXPECT_NEAR(AdaptiveSampling::pixel_error(film, 0), 0.1 / std::sqrt(0.2), 1e-5);
  EXPECT_NEAR(AdaptiveSampling::pixel_error(film, 1), 1.0 / 4.0, 1e-5);
  Film one(1, 1);
  one.add_sample(0, 0, Rgb(1.0f));
  one.set_samples(1);
  EXPECT_EQ(AdaptiveSampling::pixel_error(one, 0), INFINITY);
}

TEST(AdaptiveSampling, APixelKeepsSamplingWhileAPixelOfItsNeighbourhoodIsAboveTheThreshold) {
  // 6 x 5 pixels of 16 samples, all of one value but pixel (1, 2), whose samples alternate between 0 and 2.
  Film film(6, 5);
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 6; ++x)
      for (int k = 0; k < 16; ++k) film.add_sample(x, y, Rgb(x == 1 && y == 2 ? 2.0f * (k % 2) : 0.5f));
  film.set_samples(16);
  RenderSettings s;
  s.width = 6;
  s.height = 5;
  s.spp = 64;
  s.min_spp = 16;
  s.adaptive_threshold = 0.01;
  PixelMask active;
  EXPECT_EQ(AdaptiveSampling(s).active_pixels(film, {0, 0, 6, 5}, active), 9u);
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 6; ++x)
      EXPECT_EQ(active[static_cast<size_t>(y) * 6 + x], std::abs(x - 1) <= 1 && std::abs(y - 2) <= 1);
  // Within a region, the neighbourhood is the region's: a region that leaves the noisy pixel out has none active.
  EXPECT_EQ(AdaptiveSampling(s).active_pixels(film, {3, 0, 3, 5}, active), 0u);
  // Between decision points, the pixels that sample are those of the film's count.
  film.set_schedule_samples(20);
  for (size_t i = 0; i < 30; ++i) film.pixel_sample_counts()[i] = i % 2 ? 20 : 16;
  EXPECT_EQ(AdaptiveSampling(s).active_pixels(film, {0, 0, 6, 5}, active), 15u);
  EXPECT_EQ(active[1], 1);
  EXPECT_EQ(active[2], 0);
}

TEST(AdaptiveSampling, DecisionPointsAreEveryMinSppSamplesBelowSpp) {
  RenderSettings s = adaptive_settings();
  s.spp = 40;
  s.min_spp = 16;
  const AdaptiveSampling a(s);
  EXPECT_FALSE(a.is_decision_point(0));
  EXPECT_FALSE(a.is_decision_point(8));
  EXPECT_TRUE(a.is_decision_point(16));
  EXPECT_TRUE(a.is_decision_point(32));
  EXPECT_FALSE(a.is_decision_point(40));
  EXPECT_EQ(a.next_decision_point(0), 16u);
  EXPECT_EQ(a.next_decision_point(16), 32u);
  EXPECT_EQ(a.next_decision_point(33), 40u);
  s.adaptive_threshold = 0;
  EXPECT_EQ(AdaptiveSampling(s).next_decision_point(3), 40u);
  EXPECT_FALSE(AdaptiveSampling(s).is_decision_point(16));
}

}  // namespace
}  // namespace tessera
