// Fresnel reflectance against closed forms (Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed.,
// §2.5.3 "Fresnel Equations"; Pharr, Jakob & Humphreys, Physically Based Rendering, 3rd ed., §8.2.1).
#include <algorithm>
#include <complex>
#include <cstdio>

#include <gtest/gtest.h>

#include "renderer/bsdf/fresnel.h"

namespace tessera {
namespace {

TEST(Fresnel, NormalIncidenceIsSquaredIndexContrast) {
  for (float eta : {1.2f, 1.33f, 1.5f, 2.42f, 3.5f}) {
    const float expected = sqr((1 - eta) / (1 + eta));  // ((eta1 - eta2) / (eta1 + eta2))^2
    EXPECT_NEAR(fresnel_dielectric(1.0f, eta), expected, 1e-6f) << eta;
    EXPECT_NEAR(fresnel_dielectric(-1.0f, eta), expected, 1e-6f) << eta;  // from inside: the same
    EXPECT_NEAR(f0_from_ior(eta), expected, 1e-6f);
    // A conductor with k = 0 is a dielectric.
    EXPECT_NEAR(fresnel_conductor(1.0f, Rgb(eta), Rgb(0)).x, expected, 1e-5f);
  }
}

TEST(Fresnel, ParallelReflectanceVanishesAtBrewstersAngle) {
  for (float eta : {1.33f, 1.5f, 2.0f}) {
    // Outside: tan(theta_B) = eta2 / eta1; inside: tan(theta_B) = eta1 / eta2.
    float rs, rp;
    fresnel_dielectric_polarized(std::cos(std::atan(eta)), eta, &rs, &rp);
    EXPECT_NEAR(rp, 0.0f, 1e-6f) << eta;
    EXPECT_GT(rs, 0.01f) << eta;
    fresnel_dielectric_polarized(-std::cos(std::atan(1 / eta)), eta, &rs, &rp);
    EXPECT_NEAR(rp, 0.0f, 1e-6f) << eta;
    // Away from it R_p is not zero.
    fresnel_dielectric_polarized(std::cos(std::atan(eta) + 0.2f), eta, &rs, &rp);
    EXPECT_GT(rp, 1e-3f);
  }
}

TEST(Fresnel, TotalReflectionPastTheCriticalAngle) {
  for (float eta : {1.33f, 1.5f, 2.42f}) {
    const float critical = std::asin(1 / eta);
    for (float d : {0.001f, 0.05f, 0.3f}) {
      EXPECT_EQ(fresnel_dielectric(-std::cos(critical + d), eta), 1.0f) << eta;
    }
    EXPECT_LT(fresnel_dielectric(-std::cos(critical - 0.01f), eta), 1.0f) << eta;
    // From outside there is no total reflection; grazing incidence reflects everything in the limit.
    EXPECT_LT(fresnel_dielectric(std::cos(critical + 0.3f), eta), 1.0f);
    EXPECT_NEAR(fresnel_dielectric(1e-6f, eta), 1.0f, 1e-4f);
    Vec3 wt;
    EXPECT_FALSE(refract(Vec3(std::sin(critical + 0.01f), 0, std::cos(critical + 0.01f)), Vec3(0, 0, 1), 1 / eta, &wt));
  }
}

TEST(Fresnel, ReflectanceIsMonotoneOutsideAndBounded) {
  float prev = 0;
  for (int i = 0; i <= 100; ++i) {
    float cos_theta = 1 - i / 100.0f;
    float f = fresnel_dielectric(std::max(cos_theta, 1e-6f), 1.5f);
    EXPECT_GE(f, prev - 1e-6f);
    EXPECT_LE(f, 1.0f);
    prev = f;
  }
}

TEST(Fresnel, SnellsLawAndEnergy) {
  for (float theta : {0.1f, 0.5f, 1.0f, 1.4f}) {
    Vec3 wi(std::sin(theta), 0, std::cos(theta)), wt;
    ASSERT_TRUE(refract(wi, Vec3(0, 0, 1), 1.5f, &wt));
    EXPECT_NEAR(std::sin(theta), 1.5f * std::sqrt(1 - wt.z * wt.z), 1e-5f);
    EXPECT_LT(wt.z, 0);
    EXPECT_NEAR(length(wt), 1.0f, 1e-5f);
  }
  // The hemispherical average obeys 1 - F_ext = eta^2 (1 - F_int) (d'Eon & Irving 2011).
  for (float eta : {1.33f, 1.5f, 2.0f}) {
    EXPECT_NEAR(1 - fresnel_diffuse_reflectance(eta), eta * eta * (1 - fresnel_diffuse_reflectance(1 / eta)), 2e-3f);
  }
}

TEST(Fresnel, ConductorReflectanceOfNamedMetalsIsPlausible) {
  // Normal-incidence reflectance of gold is high in red and low in blue; silver and aluminium are bright and
  // nearly neutral; iron and chromium are greyer.
  Rgb au = fresnel_conductor(1, Rgb(0.18299f, 0.42108f, 1.3734f), Rgb(3.4242f, 2.3459f, 1.7704f));
  EXPECT_GT(au.x, 0.9f);
  EXPECT_LT(au.z, 0.5f);
  Rgb al = fresnel_conductor(1, Rgb(1.5196f, 0.96565f, 0.53124f), Rgb(7.6635f, 6.4581f, 5.0699f));
  EXPECT_GT(al.x, 0.88f);
  EXPECT_GT(al.z, 0.88f);
  // Grazing incidence reflects everything.
  EXPECT_NEAR(fresnel_conductor(1e-5f, Rgb(0.2f), Rgb(3.0f)).x, 1.0f, 1e-3f);
}

// The real-arithmetic conductor Fresnel against the complex equations, evaluated here in double precision: over
// angles from normal to near grazing and indices from the tabulated metals to dielectric-like and strongly absorbing.
TEST(Fresnel, ConductorMatchesTheComplexEquations) {
  using C = std::complex<double>;
  auto reference = [](double cos_i, double eta, double k) {
    const C n(eta, k);
    const C cos_t = std::sqrt(C(1) - (1 - cos_i * cos_i) / (n * n));
    const C r_p = (n * cos_i - cos_t) / (n * cos_i + cos_t);
    const C r_s = (cos_i - n * cos_t) / (cos_i + n * cos_t);
    return 0.5 * (std::norm(r_p) + std::norm(r_s));
  };
  int checked = 0;
  for (double eta : {0.05, 0.18299, 0.5, 1.0, 1.5196, 2.5, 4.0})
    for (double k : {0.0, 0.01, 0.5, 1.7704, 3.4242, 7.6635, 12.0})
      for (int a = 0; a <= 40; ++a) {
        const double cos_i = std::max(0.01, a / 40.0);
        const float got =
            fresnel_conductor(static_cast<float>(cos_i), Rgb(static_cast<float>(eta)), Rgb(static_cast<float>(k))).x;
        EXPECT_NEAR(got, reference(cos_i, eta, k), 4e-6) << "eta " << eta << " k " << k << " cos " << cos_i;
        ++checked;
      }
  EXPECT_EQ(checked, 7 * 7 * 41);
}

// The thin-film reflectance of Belcour & Barla 2017 (KHR_materials_iridescence): without a film (thickness 0, or a
// film of the outside's index) it is the base's own Schlick reflectance.
TEST(ThinFilmFresnel, WithoutAFilmItIsTheBasesFresnel) {
  for (const Rgb base : {Rgb(0.04f), Rgb(0.9f, 0.6f, 0.3f), Rgb(0.97f, 0.96f, 0.91f)}) {
    for (float c : {1.0f, 0.8f, 0.5f, 0.2f, 0.05f}) {
      const Rgb plain = fresnel_schlick(base, Rgb(1), c);
      const Rgb none = fresnel_thin_film(c, 1.0f, 1.3f, 0.0f, base);
      for (int i = 0; i < 3; ++i) EXPECT_NEAR(none[i], plain[i], 1e-4f) << "thickness 0, cos " << c;
    }
    // A film of the outside medium's index, at normal incidence, whatever its thickness.
    for (float d : {50.0f, 300.0f, 800.0f}) {
      const Rgb same = fresnel_thin_film(1.0f, 1.0f, 1.0f, d, base);
      for (int i = 0; i < 3; ++i) EXPECT_NEAR(same[i], base[i], 1e-4f) << "thickness " << d;
    }
  }
}

TEST(ThinFilmFresnel, StaysInZeroOneAndItsColourVariesWithThickness) {
  for (const Rgb base : {Rgb(0.04f), Rgb(0.5f), Rgb(0.95f, 0.64f, 0.54f)})
    for (float ior : {1.0f, 1.2f, 1.3f, 1.8f, 2.5f})
      for (float d = 0; d <= 1200; d += 25)
        for (float c = 0.0f; c <= 1.0f; c += 0.05f) {
          const Rgb f = fresnel_thin_film(c, 1.0f, ior, d, base);
          for (int i = 0; i < 3; ++i) {
            ASSERT_GE(f[i], 0.0f) << ior << " " << d << " " << c;
            ASSERT_LE(f[i], 1.0f) << ior << " " << d << " " << c;
          }
        }
  // A soap-like film (index 1.3) on glass (f0 0.04) seen head-on: the hue (the spread between channels) changes
  // with the thickness, and the colour at 250 nm differs from that at 400 nm and from the bare glass.
  const Rgb base(0.04f);
  float most_spread = 0, most_change = 0;
  Rgb previous = fresnel_thin_film(1.0f, 1.0f, 1.3f, 100.0f, base);
  for (float d = 100; d <= 800; d += 50) {
    const Rgb f = fresnel_thin_film(1.0f, 1.0f, 1.3f, d, base);
    most_spread = std::max(most_spread, max_component(f) - std::min({f[0], f[1], f[2]}));
    for (int i = 0; i < 3; ++i) most_change = std::max(most_change, std::abs(f[i] - previous[i]));
    previous = f;
  }
  std::printf("thin film 1.3 on f0 0.04, 100..800 nm: largest channel spread %.4f, largest change per 50 nm %.4f\n",
              most_spread, most_change);
  EXPECT_GT(most_spread, 0.01f);  // the bare glass is grey (spread 0)
  EXPECT_GT(most_change, 0.01f);
  // A metal under a film: coloured differently at two thicknesses.
  const Rgb a = fresnel_thin_film(1.0f, 1.0f, 1.8f, 250.0f, Rgb(0.9f)),
            b = fresnel_thin_film(1.0f, 1.0f, 1.8f, 400.0f, Rgb(0.9f));
  EXPECT_GT(std::max({std::abs(a[0] - b[0]), std::abs(a[1] - b[1]), std::abs(a[2] - b[2])}), 0.01f);
}

}  // namespace
}  // namespace tessera
