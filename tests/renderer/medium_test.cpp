// Unit tests of participating media (renderer/medium.h) and the Henyey–Greenstein phase function (renderer/phase.h):
// the phase function's sampling against its density by Pearson's chi-square test (as the BSDFs are tested,
// tests/materials/bsdf_harness.h), Beer–Lambert transmittance, and free-flight sampling's density and weights,
// including the single-sample MIS over channels of a chromatic medium (Chiang, Kutz and Burley 2016; Pharr, Jakob and
// Humphreys, Physically Based Rendering, 4th ed., §14.1.3).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "renderer/medium.h"
#include "renderer/phase.h"
#include "tests/renderer/test_util.h"

namespace tessera {
namespace {

float uniform01(std::mt19937_64& rng) {
  return static_cast<float>(rng() >> 40) * 0x1p-24f;
}

Vec3 unit(float theta_deg, float phi_deg) {
  const float t = theta_deg * kPi / 180, p = phi_deg * kPi / 180;
  return Vec3(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t));
}

// Directions sampled from the phase function land as often as its density says, over an equal-solid-angle grid of
// (cos theta, phi), for forward, backward, isotropic and strongly peaked lobes and several incident directions. The
// cells are integrated numerically (test_util.h) so that a peaked lobe is compared to its true cell masses.
TEST(MediaPhaseFunction, SamplingMatchesTheDensityByChiSquare) {
  const float gs[] = {0.0f, 0.3f, -0.5f, 0.8f, -0.9f, 1e-4f};
  const Vec3 wos[] = {unit(0, 0), unit(70, 30), unit(140, 250)};
  const int n = 200000;
  const int tests = static_cast<int>(std::size(gs) * std::size(wos));
  // Sidak correction: all tests together fail with probability 1 %.
  const double alpha = 1 - std::pow(1 - 0.01, 1.0 / tests);
  std::mt19937_64 rng(7);
  for (float g : gs) {
    const HenyeyGreenstein hg(g);
    for (const Vec3& wo : wos) {
      test::DirectionHistogram hist;
      for (int i = 0; i < n; ++i) {
        const Vec2 u(uniform01(rng), uniform01(rng));
        const PhaseSample s = hg.sample(wo, u);
        ASSERT_NEAR(length(s.wi), 1.0f, 1e-4f);
        ASSERT_NEAR(s.pdf, hg.pdf(wo, s.wi), 1e-3f * s.pdf + 1e-6f) << "g " << g;
        hist.add(s.wi);
      }
      const auto expected = hist.expected([&](const Vec3& wi) { return hg.pdf(wo, wi); }, n, 24);
      double total = 0;
      for (double e : expected) total += e;
      EXPECT_NEAR(total / n, 1.0, 2e-3) << "the density integrates to 1, g " << g;
      const double p = test::chi_square_p_value(hist.counts, expected);
      EXPECT_GT(p, alpha) << "g " << g << ", wo " << wo.x << " " << wo.y << " " << wo.z;
    }
  }
}

// The mean cosine of the scattering angle is g (the definition of the asymmetry parameter), and g = 0 is uniform.
TEST(MediaPhaseFunction, MeanCosineIsG) {
  std::mt19937_64 rng(3);
  const Vec3 wo = unit(30, 60);
  for (float g : {-0.7f, 0.0f, 0.4f, 0.9f}) {
    const HenyeyGreenstein hg(g);
    double sum = 0;
    const int n = 400000;
    for (int i = 0; i < n; ++i) sum += dot(-wo, hg.sample(wo, Vec2(uniform01(rng), uniform01(rng))).wi);
    EXPECT_NEAR(sum / n, g, 0.005) << g;
  }
  EXPECT_NEAR(HenyeyGreenstein(0).pdf(wo, unit(100, 10)), 1 / (4 * kPi), 1e-7);
}

// Beer–Lambert: a homogeneous slab of thickness d transmits exp(-sigma_t d) per channel, sigma_t = sigma_a + sigma_s;
// a channel that does not interact transmits everything, even over an infinite distance.
TEST(MediaHomogeneous, HomogeneousSlabTransmitsExpOfMinusSigmaTTimesThickness) {
  const HomogeneousMedium m(Rgb(0.2f, 0.0f, 1.5f), Rgb(0.3f, 0.0f, 0.5f), 0.4f);
  for (float d : {0.0f, 0.1f, 1.0f, 3.7f}) {
    const Rgb tr = m.transmittance(d);
    EXPECT_NEAR(tr.x, std::exp(-0.5 * d), 1e-6) << d;
    EXPECT_EQ(tr.y, 1.0f) << d;
    EXPECT_NEAR(tr.z, std::exp(-2.0 * d), 1e-6) << d;
  }
  const Rgb far = m.transmittance(kInfinity);
  EXPECT_EQ(far.x, 0.0f);
  EXPECT_EQ(far.y, 1.0f);
  EXPECT_EQ(far.z, 0.0f);
  EXPECT_TRUE(m.scatters());
  EXPECT_FALSE(HomogeneousMedium(Rgb(1)).scatters());
}

// Free-flight sampling's density integrates, with the probability of crossing the whole segment, to 1; and the
// distances it samples are distributed by that density (chi-square over bins of t), for a chromatic medium and
// throughputs that favour different channels.
TEST(MediaHomogeneous, FreeFlightDensityIntegratesToOneAndMatchesTheSamples) {
  const HomogeneousMedium m(Rgb(0.1f, 0.5f, 0.0f), Rgb(0.9f, 0.5f, 3.0f), 0.0f);
  const float t_max = 2.0f;
  const Rgb throughputs[] = {Rgb(1), Rgb(1, 0.01f, 0.2f), Rgb(0, 0, 1), Rgb(0)};
  std::mt19937_64 rng(11);
  for (const Rgb& beta : throughputs) {
    const Rgb pmf = m.channel_pmf(beta);
    EXPECT_NEAR(pmf.x + pmf.y + pmf.z, 1.0f, 1e-6f);
    // Numerical integral of the density over [0, t_max] (Simpson's rule, fine steps).
    const int steps = 20000;
    const double h = t_max / steps;
    double integral = 0;
    for (int i = 0; i <= steps; ++i) {
      const double w = (i == 0 || i == steps) ? 1 : (i % 2 ? 4 : 2);
      integral += w * m.free_flight_pdf(static_cast<float>(i * h), pmf);
    }
    integral *= h / 3;
    EXPECT_NEAR(integral + m.crossing_probability(t_max, pmf), 1.0, 1e-5);

    const int bins = 40, n = 200000;
    std::vector<double> observed(bins + 1, 0), expected(bins + 1, 0);
    for (int i = 0; i < n; ++i) {
      const FreeFlight f = m.sample_free_flight(t_max, beta, uniform01(rng));
      if (!f.scattered) {
        observed[bins] += 1;
        continue;
      }
      ASSERT_GE(f.t, 0.0f);
      ASSERT_LT(f.t, t_max);
      observed[std::min(bins - 1, static_cast<int>(f.t / t_max * bins))] += 1;
    }
    for (int b = 0; b < bins; ++b)
      expected[b] =
          n * test::integrate_2d([&](double t, double) { return m.free_flight_pdf(static_cast<float>(t), pmf); },
                                 t_max * b / bins, t_max * (b + 1) / bins, 0, 1, 4);
    expected[bins] = n * m.crossing_probability(t_max, pmf);
    EXPECT_GT(test::chi_square_p_value(observed, expected), 1e-3) << beta.x << " " << beta.y << " " << beta.z;
  }
}

// The weights make every channel's estimate unbiased whichever channel the distance was sampled by: the mean weight
// of the crossings is the transmittance T(t_max), and of the scattering events in [0, t_max) the integral of
// T(t) sigma_s, (sigma_s / sigma_t) (1 - T(t_max)), per channel (the two terms of the volume rendering equation,
// PBR 4th ed. §14.1). A throughput that neglects a channel must not bias it.
TEST(MediaHomogeneous, FreeFlightWeightsAreUnbiasedPerChannel) {
  const HomogeneousMedium m(Rgb(0.2f, 0.0f, 0.6f), Rgb(0.4f, 1.5f, 0.1f), 0.0f);
  const float t_max = 1.3f;
  const Rgb sigma_t = m.sigma_t();
  std::mt19937_64 rng(5);
  for (const Rgb& beta : {Rgb(1), Rgb(1, 0.05f, 0.3f), Rgb(0.02f, 1, 0.02f)}) {
    const int n = 400000;
    Rgb crossed(0), scattered(0), crossed_sq(0), scattered_sq(0);
    for (int i = 0; i < n; ++i) {
      const FreeFlight f = m.sample_free_flight(t_max, beta, uniform01(rng));
      (f.scattered ? scattered : crossed) += f.weight;
      (f.scattered ? scattered_sq : crossed_sq) += f.weight * f.weight;
    }
    for (int c = 0; c < 3; ++c) {
      const double tr = std::exp(-static_cast<double>(sigma_t[c]) * t_max);
      const double scatter = m.sigma_s()[c] / sigma_t[c] * (1 - tr);
      const double se_cross = std::sqrt(crossed_sq[c] / n) / std::sqrt(static_cast<double>(n));
      const double se_scatter = std::sqrt(scattered_sq[c] / n) / std::sqrt(static_cast<double>(n));
      EXPECT_NEAR(crossed[c] / n, tr, 4 * se_cross + 1e-6) << "channel " << c << ", beta " << beta.x;
      EXPECT_NEAR(scattered[c] / n, scatter, 4 * se_scatter + 1e-6) << "channel " << c << ", beta " << beta.x;
    }
  }
}

// Paths start in the medium around the objects and return to it when they leave an object's medium; objects do not
// nest media.
TEST(MediaHomogeneous, TrackerReturnsToTheOutsideMedium) {
  const HomogeneousMedium fog(Rgb(0.1f)), glass(Rgb(1.0f));
  MediumTracker tracker(&fog);
  EXPECT_EQ(tracker.current(), &fog);
  tracker.refract(true, &glass);
  EXPECT_EQ(tracker.current(), &glass);
  tracker.refract(false, &glass);
  EXPECT_EQ(tracker.current(), &fog);
  MediumTracker vacuum;
  vacuum.refract(false, &glass);
  EXPECT_EQ(vacuum.current(), nullptr);
}

}  // namespace
}  // namespace tessera
