// The subsurface parameters' mapping to a medium (subsurface.h), checked against van de Hulst's forward formula
// computed here independently, and the quadratic's root by the textbook formula.
#include <gtest/gtest.h>

#include <cmath>

#include "renderer/material/subsurface.h"

namespace tessera {
namespace {

// Van de Hulst's albedo of a semi-infinite medium of single-scattering albedo alpha and asymmetry g (Multiple Light
// Scattering, 1980, vol. 2, §21): (1 - s)(1 - 0.139 s) / (1 + 1.17 s), s = sqrt((1 - alpha) / (1 - g alpha)).
double van_de_hulst_albedo(double alpha, double g) {
  const double s = std::sqrt((1 - alpha) / (1 - g * alpha));
  return (1 - s) * (1 - 0.139 * s) / (1 + 1.17 * s);
}

// Inverting and going forward again gives back the multiple-scattering albedo, for every g; at g = 0 alpha is the
// smaller root of 0.139 s^2 - (1.139 + 1.17 A) s + (1 - A) = 0 squared off from 1; the ends map to the ends.
TEST(SubsurfaceMapping, InvertsVanDeHulst) {
  for (double g : {0.0, 0.3, 0.8, -0.5}) {
    for (int i = 0; i <= 20; ++i) {
      const double a = i / 20.0;
      const double alpha = subsurface_single_scattering_albedo(a, g);
      EXPECT_NEAR(van_de_hulst_albedo(alpha, g), a, 2e-4) << "A " << a << ", g " << g;
    }
  }
  for (double a : {0.1, 0.2, 0.5, 0.8, 0.95}) {
    const double b = 1.139 + 1.17 * a, c = 1 - a;
    const double s = (b - std::sqrt(b * b - 4 * 0.139 * c)) / (2 * 0.139);
    EXPECT_NEAR(subsurface_single_scattering_albedo(a, 0), 1 - s * s, 1e-4) << a;
  }
  EXPECT_NEAR(subsurface_single_scattering_albedo(0, 0), 0, 1e-4);
  EXPECT_DOUBLE_EQ(subsurface_single_scattering_albedo(1, 0), 1);
  EXPECT_DOUBLE_EQ(subsurface_single_scattering_albedo(1, 0.7), 1);
  // Whiter is more scattering, strictly.
  for (int i = 1; i <= 20; ++i)
    EXPECT_LT(subsurface_single_scattering_albedo((i - 1) / 20.0, 0), subsurface_single_scattering_albedo(i / 20.0, 0));
}

// The medium: sigma_t the inverse of each channel's mean free path, sigma_s / sigma_t the mapped albedo, g kept.
TEST(SubsurfaceMapping, MediumCoefficients) {
  SubsurfaceParams p;
  p.color = Rgb(0.2f, 0.5f, 0.8f);
  p.radius = 0.5f;
  p.radius_scale = Rgb(1.0f, 0.5f, 0.25f);
  p.anisotropy = 0.4f;
  const auto medium = subsurface_medium(p);
  const auto& h = dynamic_cast<const HomogeneousMedium&>(*medium);
  for (int c = 0; c < 3; ++c) {
    const double sigma_t = 1 / (0.5 * p.radius_scale[c]);
    EXPECT_NEAR(h.sigma_t()[c], sigma_t, 1e-4 * sigma_t) << c;
    EXPECT_NEAR(h.sigma_s()[c] / h.sigma_t()[c], subsurface_single_scattering_albedo(p.color[c], 0.4), 1e-5) << c;
    EXPECT_NEAR(van_de_hulst_albedo(h.sigma_s()[c] / h.sigma_t()[c], 0.4), p.color[c], 2e-4) << c;
  }
  EXPECT_FLOAT_EQ(h.g(), 0.4f);
}

}  // namespace
}  // namespace tessera
