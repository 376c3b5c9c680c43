// Plastic: a diffuse base under a smooth or rough dielectric coat, energy-aware.
//
// The coat reflects f_s: F(wo.z) as a mirror when smooth, F(wo.h) D G / (4 cos cos) (GGX or Beckmann) when rough.
// Light it transmits scatters in the base (albedo rho) and bounces between base and coat: of what reaches the
// base, a fraction rho (1 - F_int) / (1 - rho F_int) eventually leaves through the coat, F_int the coat's diffuse
// reflectance seen from inside (d'Eon & Irving 2011; the "internal scattering" of Mitsuba's plastic, after
// Weidlich & Wilkie 2007). The diffuse part is
//   f_d = (1 - E(mu_i)) (1 - E(mu_o)) rho (1 - F_int) / (pi (1 - E_avg) (1 - rho F_int)),
// where E(mu) is the coat's directional albedo (F(mu) when smooth; precomputed per material when rough) and
// E_avg = 2 \int E(mu) mu dmu. Then the total albedo is E(mu_o) + (1 - E(mu_o)) rho (1 - F_int) / (1 - rho F_int)
// <= 1 exactly, the model is reciprocal, and for a smooth coat f_d equals Mitsuba's
// (1 - F_i)(1 - F_o) rho / (pi eta^2 (1 - rho F_int)) because 1 - F_ext = eta^2 (1 - F_int).
// The roughness is a constant here (the table of E is built once per material).
#include <array>

#include "renderer/material/common.h"
#include "renderer/bsdf/fresnel.h"
#include "renderer/sampling.h"
#include "renderer/scene_error.h"

namespace tessera {
namespace {

constexpr int kAlbedoTableSize = 64;

struct CoatTable {
  std::array<float, kAlbedoTableSize + 1> albedo{};  // E(mu) at mu = i / kAlbedoTableSize
  float average = 0;                                 // E_avg
  float internal = 0;                                // F_int
  float at(float mu) const {
    float x = clamp(mu, 0.0f, 1.0f) * kAlbedoTableSize;
    int i = std::min(static_cast<int>(x), kAlbedoTableSize - 1);
    float t = x - i;
    return albedo[i] * (1 - t) + albedo[i + 1] * t;
  }
};

class PlasticBsdf final : public Bsdf {
 public:
  PlasticBsdf(const MicrofacetDistribution& dist, float eta, const Rgb& rho, const CoatTable* table)
      : dist_(dist), eta_(eta), rho_(rho), table_(table) {
    // rho (1 - F_int) / ((1 - E_avg)(1 - rho F_int)) / pi, per channel.
    for (int c = 0; c < 3; ++c)
      diffuse_scale_[c] =
          rho[c] * (1 - table->internal) / ((1 - table->average) * (1 - rho[c] * table->internal)) * kInvPi;
  }

  Rgb eval(const Vec3& wo_in, const Vec3& wi_in) const override {
    Vec3 wo = wo_in, wi = wi_in;
    if (!mirror_to_front(wo, wi)) return Rgb(0);
    return diffuse(wo, wi) + Rgb(specular(wo, wi));
  }

  std::optional<BsdfSample> sample(const Vec3& wo_in, float uc, Vec2 u) const override {
    if (wo_in.z == 0) return std::nullopt;
    Vec3 wo = wo_in;
    const bool flip = wo.z < 0;
    if (flip) wo.z = -wo.z;
    const float p_spec = spec_probability(wo);
    Vec3 wi;
    uint32_t lobe;
    if (uc < p_spec) {
      if (dist_.effectively_smooth()) {
        wi = reflect_local(wo);
        Rgb f(fresnel_dielectric(wo.z, eta_) / wo.z);
        if (flip) wi.z = -wi.z;
        return BsdfSample{f, wi, p_spec, kBsdfReflection | kBsdfSpecular, 1.0f};
      }
      if (!microfacet_reflection_sample(dist_, wo, u, uc / p_spec, &wi)) return std::nullopt;
      lobe = kBsdfGlossy;
    } else {
      wi = sample_cosine_hemisphere(u);
      lobe = kBsdfDiffuse;
    }
    if (wi.z <= 0) return std::nullopt;
    float pdf = pdf_front(wo, wi, p_spec);
    if (!(pdf > 0)) return std::nullopt;
    Rgb f = diffuse(wo, wi) + Rgb(specular(wo, wi));
    if (flip) wi.z = -wi.z;
    return BsdfSample{f, wi, pdf, kBsdfReflection | lobe, 1.0f};
  }

  float pdf(const Vec3& wo_in, const Vec3& wi_in) const override {
    Vec3 wo = wo_in, wi = wi_in;
    if (!mirror_to_front(wo, wi)) return 0;
    return pdf_front(wo, wi, spec_probability(wo));
  }

  uint32_t flags() const override {
    return kBsdfReflection | kBsdfDiffuse | (dist_.effectively_smooth() ? kBsdfSpecular : kBsdfGlossy);
  }
  Rgb albedo_hint() const override { return rho_; }
  float roughness_hint() const override { return dist_.roughness(); }
  Rgb eval_diffuse(const Vec3& wo_in, const Vec3& wi_in) const override {
    Vec3 wo = wo_in, wi = wi_in;
    return mirror_to_front(wo, wi) ? diffuse(wo, wi) : Rgb(0);
  }
  LobeColors lobe_colors() const override { return {rho_, Rgb(1), Rgb(0)}; }

 private:
  Rgb diffuse(const Vec3& wo, const Vec3& wi) const {
    return diffuse_scale_ * ((1 - table_->at(wi.z)) * (1 - table_->at(wo.z)));
  }
  float specular(const Vec3& wo, const Vec3& wi) const {
    if (dist_.effectively_smooth()) return 0;
    Vec3 h;
    if (!reflection_half_vector(wo, wi, &h)) return 0;
    return fresnel_dielectric(dot(wo, h), eta_) * microfacet_reflection_eval(dist_, wo, wi);
  }
  // The coat's share of what wo sees, against the diffuse luminance that leaves.
  float spec_probability(const Vec3& wo) const {
    float e = table_->at(wo.z);
    float d = (1 - e) * luminance(diffuse_scale_) * kPi * (1 - table_->average);
    return clamp(lobe_probability(e, d), 0.05f, 0.95f);
  }
  float pdf_front(const Vec3& wo, const Vec3& wi, float p_spec) const {
    float spec = dist_.effectively_smooth() ? 0.0f : microfacet_reflection_pdf(dist_, wo, wi);
    return p_spec * spec + (1 - p_spec) * cosine_hemisphere_pdf(wi.z);
  }

  MicrofacetDistribution dist_;
  float eta_;
  Rgb rho_;
  const CoatTable* table_;
  Rgb diffuse_scale_;
};

class PlasticMaterial final : public Material {
 public:
  PlasticMaterial(const MicrofacetDistribution& dist, float eta, RgbParam rho)
      : dist_(dist), eta_(eta), rho_(std::move(rho)) {
    table_.internal = fresnel_diffuse_reflectance(1 / eta);
    for (int i = 0; i <= kAlbedoTableSize; ++i) {
      float mu = std::max(static_cast<float>(i) / kAlbedoTableSize, 1e-3f);
      table_.albedo[i] = coat_albedo(mu);
    }
    // E_avg = 2 \int_0^1 E(mu) mu dmu by the trapezoidal rule on the table.
    double sum = 0;
    for (int i = 0; i < kAlbedoTableSize; ++i) {
      double m0 = static_cast<double>(i) / kAlbedoTableSize, m1 = static_cast<double>(i + 1) / kAlbedoTableSize;
      sum += 0.5 * (table_.albedo[i] * m0 + table_.albedo[i + 1] * m1) * (m1 - m0);
    }
    table_.average = static_cast<float>(2 * sum);
  }
  const Bsdf* bsdf(const ShadingPoint& sp, ScratchArena& arena) const override {
    return arena.make<PlasticBsdf>(dist_, eta_, rho_.eval(sp), &table_);
  }

 private:
  // E(mu) = \int f_s cos d(omega): F(mu) when smooth, else a deterministic stratified estimate with the
  // visible-normal sampler, whose weight for Smith masking is F(wo.m) G2 / G1(wo) (Heitz 2014, eq. 100).
  float coat_albedo(float mu) const {
    if (dist_.effectively_smooth()) return fresnel_dielectric(mu, eta_);
    const Vec3 wo(std::sqrt(1 - mu * mu), 0, mu);
    const int n = 48;
    double sum = 0;
    for (int a = 0; a < n; ++a)
      for (int b = 0; b < n; ++b) {
        Vec2 u((a + 0.5f) / n, (b + 0.5f) / n);
        Vec3 wi;
        if (!microfacet_reflection_sample(dist_, wo, u, 0.5f, &wi)) continue;
        float pdf = microfacet_reflection_pdf(dist_, wo, wi);
        if (!(pdf > 0)) continue;
        Vec3 h = normalize(wo + wi);
        sum += fresnel_dielectric(dot(wo, h), eta_) * microfacet_reflection_eval(dist_, wo, wi) * wi.z / pdf;
      }
    return static_cast<float>(sum / (n * n));
  }

  MicrofacetDistribution dist_;
  float eta_;
  RgbParam rho_;
  CoatTable table_;
};

}  // namespace

void register_plastic(MaterialRegistry& registry) {
  registry.add("plastic", [](const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
    RgbParam rho = params::rgb_param(j, "diffuse", ptr, Rgb(0.5f), 0.0f, 1.0f, ctx);
    float ior = params::number(j, "ior", ptr, 1.5f, 1.0f, 4.0f);
    if (ior == 1.0f) ior = 1.0001f;
    MicrofacetDistribution dist;
    std::string d = params::string(j, "distribution", ptr, "ggx");
    if (d == "ggx")
      dist.type = MicrofacetType::kGgx;
    else if (d == "beckmann")
      dist.type = MicrofacetType::kBeckmann;
    else
      throw SceneError(ptr + "/distribution", "must be \"ggx\" or \"beckmann\"");
    dist.alpha_x = dist.alpha_y = params::number(j, "roughness", ptr, 0.0f, 0.0f, 1.0f);
    return std::make_unique<PlasticMaterial>(dist, ior, std::move(rho));
  });
}

}  // namespace tessera
