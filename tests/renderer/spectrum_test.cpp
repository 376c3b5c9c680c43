// Wavelength sampling for dispersion (renderer/spectrum.h): the colour matching functions against the CIE 1931 table,
// the sampled wavelengths against their density (chi-square), the weights' expectation (white stays white), and the
// dispersive index against the Abbe number it is defined by.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "renderer/spectrum.h"

namespace tessera {
namespace {

using spectrum::cie_xyz;

// CIE 1931 2-degree observer, tabulated values (CIE 015:2004, table T.4) at a few wavelengths; the fit of Wyman et al.
// is within a few hundredths of them.
TEST(Spectrum, ColourMatchingFunctionsFollowTheCieTable) {
  struct Row {
    float nm, x, y, z;
  };
  for (const Row& r :
       {Row{450, 0.3362f, 0.0380f, 1.7721f}, Row{500, 0.0049f, 0.3230f, 0.2720f}, Row{555, 0.5121f, 1.0000f, 0.0057f},
        Row{600, 1.0622f, 0.6310f, 0.0008f}, Row{650, 0.2835f, 0.1070f, 0.0000f}}) {
    const Vec3 xyz = cie_xyz(r.nm);
    EXPECT_NEAR(xyz.x, r.x, 0.035f) << r.nm;
    EXPECT_NEAR(xyz.y, r.y, 0.035f) << r.nm;
    EXPECT_NEAR(xyz.z, r.z, 0.035f) << r.nm;
  }
  // D65 white (Y = 1) is sRGB's white.
  const Rgb white = spectrum::xyz_to_linear_srgb(0.95047, 1.0, 1.08883);
  EXPECT_NEAR(white.x, 1, 1e-3f);
  EXPECT_NEAR(white.y, 1, 1e-3f);
  EXPECT_NEAR(white.z, 1, 1e-3f);
}

// A path's expected weight is (1, 1, 1): light that does not depend on the wavelength keeps its colour. Over evenly
// spread numbers u the mean weight is the integral to well under a thousandth; each weight is bounded by 3.
TEST(Spectrum, TheExpectedWeightIsWhite) {
  const int n = 400000;
  Vec3 sum(0);
  float largest = 0;
  for (int k = 0; k < n; ++k) {
    const spectrum::WavelengthSample s = spectrum::sample_wavelength((k + 0.5f) / n);
    ASSERT_GE(s.lambda_nm, spectrum::kMinNm);
    ASSERT_LT(s.lambda_nm, spectrum::kMaxNm);
    ASSERT_GE(std::min({s.weight.x, s.weight.y, s.weight.z}), 0.0f);
    sum += s.weight;
    largest = std::max(largest, max_component(s.weight));
  }
  EXPECT_NEAR(sum.x / n, 1, 1e-3);
  EXPECT_NEAR(sum.y / n, 1, 1e-3);
  EXPECT_NEAR(sum.z / n, 1, 1e-3);
  EXPECT_LE(largest, 3.0f + 1e-4f);
  // The channels part: red weighs long wavelengths, blue short ones.
  EXPECT_GT(spectrum::sample_wavelength(0.9f).weight.x, spectrum::sample_wavelength(0.9f).weight.z);
  EXPECT_GT(spectrum::sample_wavelength(0.1f).weight.z, spectrum::sample_wavelength(0.1f).weight.x);
}

// The wavelengths drawn follow wavelength_pdf: Pearson's chi-square over 20 nm bins of 200,000 independent draws
// (bins expecting fewer than 5 pooled), against the 0.1 % critical value of its degrees of
// freedom (Wilson-Hilferty).
TEST(Spectrum, SampledWavelengthsFollowTheirDensity) {
  const int bins = 20, n = 200000;
  const float width = (spectrum::kMaxNm - spectrum::kMinNm) / bins;
  std::vector<double> observed(bins, 0), expected(bins, 0);
  uint64_t state = 0x9e3779b97f4a7c15ULL;
  for (int k = 0; k < n; ++k) {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    const float u = static_cast<float>(state >> 40) * 0x1p-24f;
    const float nm = spectrum::sample_wavelength(u).lambda_nm;
    observed[std::min(bins - 1, static_cast<int>((nm - spectrum::kMinNm) / width))] += 1;
  }
  for (int b = 0; b < bins; ++b)
    for (int i = 0; i < 20; ++i) expected[b] += spectrum::wavelength_pdf(spectrum::kMinNm + b * width + i + 0.5f) * n;
  // Bins expecting fewer than 5 draws (the ends of the range) are pooled into one.
  double chi2 = 0, pooled_observed = 0, pooled_expected = 0;
  int dof = -1;
  const auto add = [&](double o, double e) {
    chi2 += sqr(static_cast<float>(o - e)) / e;
    ++dof;
  };
  for (int b = 0; b < bins; ++b) {
    if (expected[b] < 5) {
      pooled_observed += observed[b];
      pooled_expected += expected[b];
    } else {
      add(observed[b], expected[b]);
    }
  }
  if (pooled_expected >= 5)
    add(pooled_observed, pooled_expected);
  else
    EXPECT_LE(pooled_observed, 15);
  const double z = 3.09;  // the 0.1 % upper quantile of the normal distribution
  const double critical = dof * std::pow(1 - 2.0 / (9 * dof) + z * std::sqrt(2.0 / (9 * dof)), 3);
  EXPECT_LT(chi2, critical) << dof << " degrees of freedom";
}

// KHR_materials_dispersion's index: ior at the d line (587.6 nm), and V_d = (n_d - 1) / (n_F - n_C) = 20 / dispersion
// between the F (486.1 nm) and C (656.3 nm) lines; never below 1; no dispersion, no change.
TEST(Spectrum, TheDispersiveIndexHasTheAbbeNumberItIsGiven) {
  for (float ior : {1.33f, 1.5f, 2.42f})
    for (float dispersion : {0.33f, 1.0f, 2.04f}) {
      EXPECT_NEAR(spectrum::dispersive_ior(ior, dispersion, 587.56f), ior, 1e-4f);
      const float nf = spectrum::dispersive_ior(ior, dispersion, 486.13f),
                  nc = spectrum::dispersive_ior(ior, dispersion, 656.27f);
      EXPECT_GT(nf, nc);
      EXPECT_NEAR((ior - 1) / (nf - nc), 20 / dispersion, 0.01f * 20 / dispersion) << ior << " " << dispersion;
    }
  EXPECT_EQ(spectrum::dispersive_ior(1.5f, 0, 400), 1.5f);
  EXPECT_EQ(spectrum::dispersive_ior(1.05f, 100, 700), 1.0f);
}

}  // namespace
}  // namespace tessera
