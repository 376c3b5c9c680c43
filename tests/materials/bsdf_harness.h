// The one harness every material model is tested through (Mitsuba's chi2 tests and pbrt-v4's bsdfs_test are the
// models): a table of parameter sets per registered model type, incident directions, a (cos theta, phi) histogram
// of `sample` against the numerically integrated `pdf`, and Pearson's chi-square test with Sidak correction.
#pragma once

#include <cstdint>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "renderer/arena.h"
#include "renderer/material/material.h"
#include "tests/renderer/test_util.h"

namespace tessera::test {

struct BsdfCase {
  std::string name;         // unique, for test names
  nlohmann::json material;  // the material document
  bool transmissive = false;
  // A coating layer's own normal at the shading point (ShadingPoint::coat_normal), zero for none.
  Vec3 coat_normal{0, 0, 0};
};

void PrintTo(const BsdfCase& c, std::ostream* os);

// Every parameter set of every non-delta model: several per model, including very low and very high roughness and
// strong anisotropy.
const std::vector<BsdfCase>& bsdf_cases();
// Model types with no non-delta lobe to test statistically (tested by their own tests).
const std::vector<std::string>& delta_only_types();
// Model types that are deliberately not energy conserving or reciprocal (the classic Phong forms, Dutré et al.,
// Advanced Global Illumination, 2nd ed., §2.5.4).
bool is_classic(const std::string& type);

// Incident directions (wo) for a case: near-normal, 35 and 65 degrees, grazing (87 degrees) and from the back side
// (for transmissive cases from inside, including one past the critical angle of total internal reflection).
std::vector<Vec3> incident_directions(const BsdfCase& c);
// 10 incident directions from normal to grazing, for directional albedo.
std::vector<Vec3> albedo_directions();

// The total number of chi-square tests (for the Sidak correction).
int chi2_test_count();

// Holds a material and the BSDF it builds at a default shading point (local frame = world frame).
class BsdfInstance {
 public:
  explicit BsdfInstance(const nlohmann::json& material, const Vec3& coat_normal = Vec3(0, 0, 0));
  explicit BsdfInstance(const BsdfCase& c) : BsdfInstance(c.material, c.coat_normal) {}
  const Bsdf& bsdf() const { return *bsdf_; }
  bool has_bsdf() const { return bsdf_ != nullptr; }

 private:
  std::unique_ptr<Material> material_;
  ScratchArena arena_;
  ShadingPoint sp_;
  const Bsdf* bsdf_ = nullptr;
};

// A uniform float in [0, 1) from a 64-bit generator (24 random bits: never rounds up to 1).
inline float uniform01(std::mt19937_64& rng) {
  return static_cast<float>(rng() >> 40) * 0x1p-24f;
}

Vec3 direction(float theta_deg, float phi_deg);

struct Chi2Result {
  double statistic = 0;
  int dof = 0;
  double p_value = 1;
  double pdf_integral = 0;      // \int pdf over the sphere
  double sampled_fraction = 0;  // non-delta samples / all samples
  std::string failure;          // non-empty: a sample landed where pdf is zero, or the like
};

// Samples `n` directions from bsdf.sample(wo), bins the non-delta ones over an 80 x 160 grid in (cos theta, phi),
// integrates pdf over each cell by adaptive Simpson cubature, pools cells expecting fewer than 5, treats discarded
// and delta samples as one extra cell expecting n (1 - \int pdf), and returns Pearson's statistic and p-value.
Chi2Result chi2_test(const Bsdf& bsdf, const Vec3& wo, int n, uint64_t seed);

// gamma_q, the chi-square survival function's building block, is shared with the renderer tests (test_util.h).

}  // namespace tessera::test
