// glTF material extensions in the gltf_pbr model. KHR_materials_anisotropy: the specular lobe is anisotropic GGX with
// alpha_t = mix(alpha, 1, strength^2) along the anisotropy direction (the tangent turned by the rotation) and alpha_b =
// alpha across it, so a highlight seen head-on is stretched along that direction. KHR_materials_diffuse_transmission: a
// Lambertian lobe into the other hemisphere sharing the diffuse lobe with the base colour. KHR_materials_iridescence:
// the specular Fresnel mixed with the thin-film Fresnel of Belcour and Barla 2017.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "bsdf_harness.h"
#include "renderer/bsdf/fresnel.h"

namespace tessera::test {
namespace {

using nlohmann::json;

// The mean squared components of sampled directions along the unit direction d = (cos r, sin r) in the tangent plane
// and across it, for a smooth metal lit head-on.
void spread(float strength, float rotation, double* along, double* across) {
  BsdfInstance b(json{{"type", "gltf_pbr"},
                      {"metallic", 1},
                      {"roughness", 0.3},
                      {"anisotropy", strength},
                      {"anisotropy_rotation", rotation}});
  std::mt19937_64 rng(7);
  const float c = std::cos(rotation), s = std::sin(rotation);
  double a = 0, x = 0;
  int n = 0;
  for (int i = 0; i < 20000; ++i) {
    const auto smp = b.bsdf().sample(direction(0.5f, 0), uniform01(rng), Vec2(uniform01(rng), uniform01(rng)));
    if (!smp) continue;
    a += sqr(c * smp->wi.x + s * smp->wi.y);
    x += sqr(-s * smp->wi.x + c * smp->wi.y);
    ++n;
  }
  ASSERT_GT(n, 15000);
  *along = a / n;
  *across = x / n;
}

TEST(GltfAnisotropy, TheHighlightStretchesAlongTheRotatedTangent) {
  // alpha 0.09 across; along: 0.09 + 0.91 * 0.8^2 = 0.67. The sampled directions' spread in the tangent plane
  // follows the roughness: far wider along the direction than across it, whichever way the direction is turned.
  for (float rotation : {0.0f, 0.7f, 1.5708f, -2.2f}) {
    double along, across;
    spread(0.8f, rotation, &along, &across);
    EXPECT_GT(along, 4 * across) << "rotation " << rotation << ": " << along << " vs " << across;
  }
  // Without anisotropy the spread is the same both ways (within 5 % at 20000 samples).
  double along, across;
  spread(0.0f, 0.7f, &along, &across);
  EXPECT_NEAR(along / across, 1.0, 0.05);
}

// Reflected and transmitted albedo at wo: the mean of f |cos| / pdf over `n` samples, split by side, with the
// standard error of their sum.
void albedo(const Bsdf& bsdf, const Vec3& wo, int n, double* reflected, double* transmitted, double* error) {
  std::mt19937_64 rng(11);
  double r = 0, t = 0, sum2 = 0;
  for (int i = 0; i < n; ++i) {
    const auto s = bsdf.sample(wo, uniform01(rng), Vec2(uniform01(rng), uniform01(rng)));
    if (!s || !(s->pdf > 0)) continue;
    const double w = max_component(s->f) * std::abs(s->wi.z) / s->pdf;
    (s->wi.z * wo.z > 0 ? r : t) += w;
    sum2 += w * w;
  }
  *reflected = r / n;
  *transmitted = t / n;
  const double mean = (r + t) / n;
  *error = std::sqrt(std::max(0.0, sum2 / n - mean * mean) / n);
}

TEST(GltfDiffuseTransmission, AWhiteSurfaceThatTransmitsAllItsDiffuseLightKeepsItsEnergy) {
  // White furnace: a white dielectric whose diffuse lobe is all transmitted, in white, reflects its specular albedo
  // E_s(mu_o) and transmits the rest, 1 - E_s(mu_o), summing to 1 at every angle (within the albedo table's
  // interpolation, 1 %, and 4 standard errors).
  BsdfInstance b(json{{"type", "gltf_pbr"}, {"metallic", 0}, {"roughness", 0.5}, {"diffuse_transmission", 1}});
  for (float theta : {0.0f, 30.0f, 60.0f, 80.0f}) {
    for (float side : {1.0f, -1.0f}) {
      Vec3 wo = direction(theta, 20);
      wo.z *= side;
      double r, t, e;
      albedo(b.bsdf(), wo, 200000, &r, &t, &e);
      std::printf("[furnace] theta %2.0f side %+.0f: reflected %.4f + transmitted %.4f = %.4f (+- %.4f)\n", theta, side,
                  r, t, r + t, e);
      EXPECT_NEAR(r + t, 1.0, 0.01 + 4 * e) << "theta " << theta << " side " << side << ": " << r << " + " << t;
      EXPECT_GT(t, 0.6) << "theta " << theta;   // the diffuse light goes through
      EXPECT_GT(r, 0.02) << "theta " << theta;  // the specular reflection stays
    }
  }
  // Half transmitted, in a colour: the transmitted albedo takes it, the reflected diffuse the base colour.
  BsdfInstance h(json{{"type", "gltf_pbr"},
                      {"metallic", 0},
                      {"roughness", 0.5},
                      {"base_color", {1, 1, 1}},
                      {"diffuse_transmission", 0.5},
                      {"diffuse_transmission_color", {0.2, 0.2, 0.2}}});
  double r, t, e;
  albedo(h.bsdf(), direction(0, 0), 200000, &r, &t, &e);
  // Diffuse share 1 - E_s(1) ~ 0.96 at normal incidence: transmitted 0.5 * 0.2 of it, reflected 0.5 of it + E_s.
  EXPECT_NEAR(t, 0.1 * (1 - r + t) / (1 - 0.4), 0.01 + 4 * e);  // t = 0.1 D, r = E_s + 0.5 D, so D = (1 - r + t) / 0.6
}

// KHR_materials_iridescence: a metal's Fresnel becomes mix(F, F_film, iridescence). Seen and lit head-on (the half
// vector is the normal, V.H = 1) the BSDF's value divided by the bare metal's is that mix over the base's Fresnel,
// per channel, and it changes colour with the film's thickness.
TEST(GltfIridescence, TheMetalReflectsTheThinFilmsFresnel) {
  const Rgb base(0.9f, 0.6f, 0.3f);
  auto eval = [&](float iridescence, float thickness) {
    BsdfInstance b(json{{"type", "gltf_pbr"},
                        {"metallic", 1},
                        {"roughness", 0.4},
                        {"base_color", {base[0], base[1], base[2]}},
                        {"iridescence", iridescence},
                        {"iridescence_ior", 1.8},
                        {"iridescence_thickness_minimum", thickness},
                        {"iridescence_thickness_maximum", thickness}});
    return b.bsdf().eval(direction(0, 0), direction(0, 0));
  };
  const Rgb bare = eval(0, 300);
  for (float thickness : {250.0f, 400.0f})
    for (float weight : {1.0f, 0.5f}) {
      const Rgb film = fresnel_thin_film(1.0f, 1.0f, 1.8f, thickness, base);
      const Rgb f = eval(weight, thickness);
      for (int i = 0; i < 3; ++i) {
        const float expected = (1 - weight) + weight * film[i] / base[i];  // Schlick at V.H = 1 is base
        EXPECT_NEAR(f[i] / bare[i], expected, 1e-3f * expected) << thickness << " nm, weight " << weight << ", " << i;
      }
    }
  const Rgb a = eval(1, 250), b = eval(1, 400);
  EXPECT_GT(std::abs(a[0] / a[2] - b[0] / b[2]), 0.05f);  // the hue changes with the thickness
}

}  // namespace
}  // namespace tessera::test
