// KHR_materials_anisotropy in the gltf_pbr model: the specular lobe is anisotropic GGX with alpha_t = mix(alpha, 1,
// strength^2) along the anisotropy direction (the tangent turned by the rotation) and alpha_b = alpha across it, so a
// highlight seen head-on is stretched along that direction.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "bsdf_harness.h"

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

}  // namespace
}  // namespace tessera::test
