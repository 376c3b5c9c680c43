// Energy and reciprocity of every model: directional albedo <= 1.01 at 10 incident directions, R + T = 1 for a
// lossless smooth dielectric, f(wo, wi) = f(wi, wo) where the model should be reciprocal, and the classic
// Phong / Blinn-Phong (Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed., §2.5.4) shown to break both while
// the modified forms keep them.
#include <cstdio>

#include <gtest/gtest.h>

#include "bsdf_harness.h"
#include "renderer/bsdf/fresnel.h"

namespace tessera::test {
namespace {

using nlohmann::json;

// Directional albedo \int f |cos| d(omega_i) (with the eta^2 of refraction taken out, so that it measures energy)
// by importance sampling with the model's own sampler; delta lobes included.
Rgb directional_albedo(const Bsdf& bsdf, const Vec3& wo, int n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  double sum[3] = {0, 0, 0};
  for (int i = 0; i < n; ++i) {
    std::optional<BsdfSample> s = bsdf.sample(wo, uniform01(rng), Vec2(uniform01(rng), uniform01(rng)));
    if (!s || !(s->pdf > 0)) continue;
    float scale = std::abs(s->wi.z) / s->pdf;
    if (s->flags & kBsdfTransmission) scale *= s->eta * s->eta;
    for (int c = 0; c < 3; ++c) sum[c] += s->f[c] * scale;
  }
  return Rgb(static_cast<float>(sum[0] / n), static_cast<float>(sum[1] / n), static_cast<float>(sum[2] / n));
}

std::vector<std::pair<std::string, json>> energy_cases() {
  std::vector<std::pair<std::string, json>> out;
  for (const BsdfCase& c : bsdf_cases()) {
    if (!is_classic(c.material["type"])) out.emplace_back(c.name, c.material);
  }
  // Every registered model at its defaults, and the delta models.
  for (const std::string& type : MaterialRegistry::builtin().types()) {
    if (!is_classic(type)) out.emplace_back(type + "_defaults", json{{"type", type}});
  }
  out.emplace_back("dielectric_smooth_glass", json{{"type", "dielectric"}, {"ior", 1.5}});
  out.emplace_back("dielectric_smooth_diamond", json{{"type", "dielectric"}, {"ior", 2.42}});
  out.emplace_back("thin_dielectric", json{{"type", "thin_dielectric"}, {"ior", 1.5}});
  out.emplace_back("conductor_smooth_silver", json{{"type", "conductor"}, {"metal", "silver"}});
  out.emplace_back("plastic_white", json{{"type", "plastic"}, {"diffuse", 1.0}, {"roughness", 0.3}});
  out.emplace_back("plastic_white_smooth", json{{"type", "plastic"}, {"diffuse", 1.0}});
  out.emplace_back("gltf_white_dielectric", json{{"type", "gltf_pbr"}, {"metallic", 0}, {"roughness", 0.3}});
  // A white dielectric under a thin film at the thicknesses where the film reflects most and least: the film's
  // Fresnel replaces Schlick's in the specular lobe, while the diffuse lobe's share is still Schlick's albedo.
  for (double nm : {120.0, 300.0, 550.0})
    for (double roughness : {0.2, 0.6})
      out.emplace_back("gltf_white_iridescent_" + std::to_string(static_cast<int>(nm)) + "nm_r" +
                           std::to_string(static_cast<int>(roughness * 10)),
                       json{{"type", "gltf_pbr"},
                            {"metallic", 0},
                            {"roughness", roughness},
                            {"iridescence", 1},
                            {"iridescence_ior", 1.8},
                            {"iridescence_thickness_maximum", nm}});
  out.emplace_back("gltf_white_diffuse_transmission",
                   json{{"type", "gltf_pbr"}, {"metallic", 0}, {"roughness", 0.5}, {"diffuse_transmission", 1}});
  out.emplace_back("cook_torrance_white_kd",
                   json{{"type", "cook_torrance"}, {"kd", 0.5}, {"ks", 0.5}, {"roughness", 0.5}});
  return out;
}

TEST(Energy, DirectionalAlbedoAtMostOne) {
  int n_models = 0;
  for (const auto& [name, material] : energy_cases()) {
    BsdfInstance inst(material);
    if (!inst.has_bsdf()) continue;
    ++n_models;
    std::string line;
    float worst = 0;
    int k = 0;
    for (const Vec3& wo : albedo_directions()) {
      Rgb a = directional_albedo(inst.bsdf(), wo, 100000, 99 + k++);
      worst = std::max(worst, max_component(a));
      char buf[32];
      std::snprintf(buf, sizeof buf, " %.3f", max_component(a));
      line += buf;
      EXPECT_LE(max_component(a), 1.01f) << name << " at cos(theta_o) = " << wo.z;
      EXPECT_GE(std::min(a.x, std::min(a.y, a.z)), 0.0f) << name;
    }
    std::printf("[albedo] %-30s max %.4f  by angle 0..88 deg:%s\n", name.c_str(), worst, line.c_str());
  }
  EXPECT_GT(n_models, 30);
}

TEST(Energy, LosslessSmoothDielectricReflectsPlusTransmitsOne) {
  for (float ior : {1.33f, 1.5f, 2.42f}) {
    BsdfInstance inst(json{{"type", "dielectric"}, {"ior", ior}});
    const Bsdf& bsdf = inst.bsdf();
    for (float theta : {0.0f, 30.0f, 60.0f, 85.0f, 150.0f, 170.0f, 120.0f, 100.0f}) {
      Vec3 wo = direction(theta, 10);
      std::mt19937_64 rng(7);
      double reflected = 0, transmitted = 0;
      const int n = 20000;
      for (int i = 0; i < n; ++i) {
        auto s = bsdf.sample(wo, uniform01(rng), Vec2(uniform01(rng), uniform01(rng)));
        ASSERT_TRUE(s.has_value());
        double w = s->f.x * std::abs(s->wi.z) / s->pdf;
        if (s->flags & kBsdfTransmission) {
          transmitted += w * s->eta * s->eta;
          // Snell's law: eta_o sin(theta_o) = eta_i sin(theta_i), with eta' = eta_i / eta_o.
          float sin_o = std::sqrt(1 - wo.z * wo.z), sin_i = std::sqrt(1 - s->wi.z * s->wi.z);
          EXPECT_NEAR(sin_o, s->eta * sin_i, 1e-4f);
          EXPECT_NEAR(s->eta, wo.z > 0 ? ior : 1 / ior, 1e-6f);
        } else {
          reflected += w;
        }
      }
      const double R = fresnel_dielectric(wo.z, ior);
      EXPECT_NEAR((reflected + transmitted) / n, 1.0, 1e-5) << "ior " << ior << " theta " << theta;
      // Each sample carries weight exactly 1: R and T show in how often each lobe is taken.
      EXPECT_NEAR(reflected / n, R, 4 * std::sqrt(R * (1 - R) / n) + 1e-6) << "ior " << ior << " theta " << theta;
    }
  }
}

// f(wo, wi) eta(wi)^2 = f(wi, wo) eta(wo)^2, eta(w) the index on w's side: plain reciprocity for reflection, the
// generalised form of Veach 1997 (eq. 5.14) for the radiance BTDF.
TEST(Reciprocity, HoldsForEveryModelThatShouldHaveIt) {
  for (const BsdfCase& c : bsdf_cases()) {
    if (is_classic(c.material["type"])) continue;
    BsdfInstance inst(c);
    const Bsdf& bsdf = inst.bsdf();
    const std::string type = c.material["type"];
    const bool refracts = type == "dielectric" || (type == "gltf_pbr" && !c.material.value("thin_walled", true));
    const float ior = refracts ? c.material.value("ior", 1.5f) : 1.0f;
    const bool check_transmission = type != "two_sided";
    std::mt19937_64 rng(3);
    int checked = 0;
    for (int i = 0; i < 20000; ++i) {
      Vec3 a = direction(std::acos(1 - 2 * uniform01(rng)) * 180 / kPi, 360 * uniform01(rng));
      Vec3 b = direction(std::acos(1 - 2 * uniform01(rng)) * 180 / kPi, 360 * uniform01(rng));
      if (std::abs(a.z) < 0.02f || std::abs(b.z) < 0.02f) continue;
      if (a.z * b.z < 0 && !check_transmission) continue;
      auto eta = [&](const Vec3& w) { return w.z < 0 ? ior : 1.0f; };
      Rgb fab = bsdf.eval(a, b) * sqr(eta(b));
      Rgb fba = bsdf.eval(b, a) * sqr(eta(a));
      for (int ch = 0; ch < 3; ++ch) {
        ASSERT_NEAR(fab[ch], fba[ch], 1e-3f * std::max(1.0f, std::max(fab[ch], fba[ch])))
            << c.name << " a=(" << a.x << "," << a.y << "," << a.z << ") b=(" << b.x << "," << b.y << "," << b.z << ")";
      }
      if (!is_black(fab)) ++checked;
    }
    EXPECT_GT(checked, 100) << c.name;
  }
}

// The adjoint BSDF of importance transport is f with its arguments swapped (Veach 1997, 3.7.6): f*(a, b) = f(b, a)
// for every model, whatever it does across refraction (the radiance BTDF's 1/eta'^2 is absent from the adjoint);
// and its non-delta samples report f*. (two_sided shows the front side from both sides: across it the model is not
// reciprocal to begin with, and its transmission pairs are left out as in the reciprocity test.)
TEST(Adjoint, EvalIsTheBsdfWithItsArgumentsSwapped) {
  for (const BsdfCase& c : bsdf_cases()) {
    if (is_classic(c.material["type"])) continue;
    BsdfInstance inst(c);
    const Bsdf& bsdf = inst.bsdf();
    const bool check_transmission = c.material["type"] != "two_sided";
    std::mt19937_64 rng(5);
    int transmitted = 0;
    for (int i = 0; i < 4000; ++i) {
      Vec3 a = direction(std::acos(1 - 2 * uniform01(rng)) * 180 / kPi, 360 * uniform01(rng));
      Vec3 b = direction(std::acos(1 - 2 * uniform01(rng)) * 180 / kPi, 360 * uniform01(rng));
      if (std::abs(a.z) < 0.02f || std::abs(b.z) < 0.02f) continue;
      if (a.z * b.z < 0 && !check_transmission) continue;
      const Rgb adjoint = bsdf.eval_for(TransportMode::kImportance, a, b);
      const Rgb swapped = bsdf.eval(b, a);
      for (int ch = 0; ch < 3; ++ch)
        ASSERT_NEAR(adjoint[ch], swapped[ch], 1e-3f * std::max(1.0f, std::max(adjoint[ch], swapped[ch]))) << c.name;
      if (a.z * b.z < 0 && !is_black(swapped)) ++transmitted;
      // Non-delta samples of the adjoint report the adjoint's value.
      auto s = bsdf.sample_for(TransportMode::kImportance, a, uniform01(rng), Vec2(uniform01(rng), uniform01(rng)));
      if (s && !is_delta(s->flags)) {
        const Rgb f = bsdf.eval_adjoint(a, s->wi);
        for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(s->f[ch], f[ch], 1e-3f * std::max(1.0f, f[ch])) << c.name;
      }
    }
    if (c.transmissive && (c.material["type"] == "dielectric" || c.material["type"] == "gltf_pbr")) {
      EXPECT_GT(transmitted, 100) << c.name;
    }
  }
}

TEST(Adjoint, SmoothDielectricTransmitsImportanceWithoutTheEtaSquaredFactor) {
  // Through a lossless smooth interface the importance weights are R and 1 - R with no 1/eta'^2: a light path's
  // throughput across glass is not scaled the way radiance is.
  for (float ior : {1.33f, 1.5f}) {
    BsdfInstance inst(json{{"type", "dielectric"}, {"ior", ior}});
    for (float theta : {0.0f, 40.0f, 150.0f}) {
      const Vec3 wo = direction(theta, 10);
      std::mt19937_64 rng(9);
      for (int i = 0; i < 200; ++i) {
        auto s = inst.bsdf().sample_for(TransportMode::kImportance, wo, uniform01(rng),
                                        Vec2(uniform01(rng), uniform01(rng)));
        ASSERT_TRUE(s.has_value());
        EXPECT_NEAR(s->f.x * std::abs(s->wi.z) / s->pdf, 1.0, 1e-5) << "ior " << ior << " theta " << theta;
      }
    }
  }
}

// Dutré et al., §2.5.4: the Phong and Blinn-Phong models as first written (with 1/(N.Psi)) are "not energy conserving"
// and do "not satisfy Helmholtz's reciprocity"; the modified, normalised forms are both.
TEST(ClassicShadingModels, BreakReciprocityAndEnergyWhileModifiedFormsKeepThem) {
  for (const std::string& base : {std::string("phong"), std::string("blinn_phong")}) {
    json params = {{"kd", 0.0}, {"ks", 1.0}, {"exponent", 1}};
    json classic = params, modified = params;
    classic["type"] = base + "_classic";
    modified["type"] = base;
    BsdfInstance c(classic), m(modified);
    // Energy: at normal incidence the classic lobe reflects ks \int cos^n d(omega), about pi for n = 1.
    Vec3 wo = direction(0.5f, 0);
    float albedo_classic = max_component(directional_albedo(c.bsdf(), wo, 200000, 1));
    float albedo_modified = max_component(directional_albedo(m.bsdf(), wo, 200000, 1));
    std::printf("[classic] %s: albedo at normal incidence classic %.3f, modified %.3f\n", base.c_str(), albedo_classic,
                albedo_modified);
    EXPECT_GT(albedo_classic, 1.5f) << base;
    EXPECT_LE(albedo_modified, 1.01f) << base;
    EXPECT_GE(albedo_modified, 0.95f) << base;  // ks = 1 at normal incidence reflects (nearly) everything
    // Reciprocity at a pair of directions with different elevations.
    Vec3 a = direction(10, 0), b = direction(70, 180);
    float ratio_classic = c.bsdf().eval(a, b).x / c.bsdf().eval(b, a).x;
    float ratio_modified = m.bsdf().eval(a, b).x / m.bsdf().eval(b, a).x;
    std::printf("[classic] %s: f(a,b)/f(b,a) classic %.3f, modified %.6f\n", base.c_str(), ratio_classic,
                ratio_modified);
    EXPECT_GT(std::abs(ratio_classic - 1), 0.5f) << base;
    EXPECT_NEAR(ratio_modified, 1.0f, 1e-5f) << base;
  }
}

}  // namespace
}  // namespace tessera::test
