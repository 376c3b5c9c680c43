// Cook-Torrance microfacet reflection (Cook & Torrance 1982; Dutré, Bala & Bekaert, Advanced
// Global Illumination, 2nd ed., §2.5.4 "Cook-Torrance model"), in the form
//   f = kd/pi + ks F(wo.h) D(h) G(wo, wi) / (4 |N.wi| |N.wo|)                         (Walter 2007, eq. 20)
// with D Beckmann (Dutré et al.'s) or GGX, isotropic or anisotropic along the tangent, G the V-cavity term or
// height-correlated Smith masking, and F the dielectric Fresnel of "ior" or a conductor's (microfacet.h).
//
// Where Dutré et al. differ: their f = F/pi * D G / ((N.Psi)(N.Theta)) + k_d uses a D without the 1/pi of the
// projected-area normalisation (microfacet.h) and a factor 1 where the Jacobian of the half-vector mapping,
// d(omega_h)/d(omega_i) = 1/(4 |o.h|) (Walter 2007, eq. 14), gives 1/4; with the normalised D used here their
// expression would reflect 4 times too much. Sampling: visible normals of D (V-cavity or Smith) for the
// specular lobe, cosine for the diffuse one, chosen by the luminances of kd and ks. kd + ks <= 1 per channel keeps
// the albedo at most 1.
#include "renderer/material/common.h"
#include "renderer/bsdf/fresnel.h"
#include "renderer/sampling.h"
#include "renderer/scene_error.h"

namespace tessera {
namespace {

struct CtFresnel {
  bool conductor = false;
  float ior = 1.5f;
  Rgb eta, k;
  Rgb eval(float cos_theta) const {
    return conductor ? fresnel_conductor(cos_theta, eta, k) : Rgb(fresnel_dielectric(std::abs(cos_theta), ior));
  }
};

class CookTorranceBsdf final : public Bsdf {
 public:
  CookTorranceBsdf(const MicrofacetDistribution& dist, const CtFresnel& fresnel, const Rgb& kd, const Rgb& ks)
      : dist_(dist), fresnel_(fresnel), kd_(kd), ks_(ks), p_diffuse_(lobe_probability(luminance(kd), luminance(ks))) {}

  Rgb eval(const Vec3& wo_in, const Vec3& wi_in) const override {
    Vec3 wo = wo_in, wi = wi_in;
    if (!mirror_to_front(wo, wi)) return Rgb(0);
    return kd_ * kInvPi + specular(wo, wi);
  }

  std::optional<BsdfSample> sample(const Vec3& wo_in, float uc, Vec2 u) const override {
    if (wo_in.z == 0) return std::nullopt;
    Vec3 wo = wo_in;
    const bool flip = wo.z < 0;
    if (flip) wo.z = -wo.z;
    Vec3 wi;
    BsdfSample s;
    if (uc < p_diffuse_) {
      wi = sample_cosine_hemisphere(u);
      s.flags = kBsdfReflection | kBsdfDiffuse;
    } else if (dist_.effectively_smooth()) {
      wi = reflect_local(wo);
      s.f = ks_ * fresnel_.eval(wo.z) / wo.z;
      s.pdf = 1 - p_diffuse_;
      s.flags = kBsdfReflection | kBsdfSpecular;
      s.wi = flip ? Vec3(wi.x, wi.y, -wi.z) : wi;
      return s;
    } else {
      float u_extra = (uc - p_diffuse_) / (1 - p_diffuse_);
      if (!microfacet_reflection_sample(dist_, wo, u, u_extra, &wi)) return std::nullopt;
      s.flags = kBsdfReflection | kBsdfGlossy;
    }
    if (wi.z <= 0) return std::nullopt;
    s.pdf = pdf_front(wo, wi);
    if (!(s.pdf > 0)) return std::nullopt;
    s.f = kd_ * kInvPi + specular(wo, wi);
    s.wi = flip ? Vec3(wi.x, wi.y, -wi.z) : wi;
    return s;
  }

  float pdf(const Vec3& wo_in, const Vec3& wi_in) const override {
    Vec3 wo = wo_in, wi = wi_in;
    if (!mirror_to_front(wo, wi)) return 0;
    return pdf_front(wo, wi);
  }

  uint32_t flags() const override {
    uint32_t f = kBsdfReflection | (dist_.effectively_smooth() ? kBsdfSpecular : kBsdfGlossy);
    if (!is_black(kd_)) f |= kBsdfDiffuse;
    return f;
  }
  Rgb albedo_hint() const override { return kd_ + ks_ * fresnel_.eval(1); }
  float roughness_hint() const override { return dist_.roughness(); }
  Rgb eval_diffuse(const Vec3& wo_in, const Vec3& wi_in) const override {
    Vec3 wo = wo_in, wi = wi_in;
    return mirror_to_front(wo, wi) ? kd_ * kInvPi : Rgb(0);
  }
  LobeColors lobe_colors() const override { return {kd_, ks_ * fresnel_.eval(1), Rgb(0)}; }

 private:
  Rgb specular(const Vec3& wo, const Vec3& wi) const {
    if (dist_.effectively_smooth()) return Rgb(0);
    Vec3 h;
    if (!reflection_half_vector(wo, wi, &h)) return Rgb(0);
    return ks_ * fresnel_.eval(dot(wo, h)) * microfacet_reflection_eval(dist_, wo, wi);
  }
  float pdf_front(const Vec3& wo, const Vec3& wi) const {
    float spec = dist_.effectively_smooth() ? 0.0f : microfacet_reflection_pdf(dist_, wo, wi);
    return p_diffuse_ * cosine_hemisphere_pdf(wi.z) + (1 - p_diffuse_) * spec;
  }

  MicrofacetDistribution dist_;
  CtFresnel fresnel_;
  Rgb kd_, ks_;
  float p_diffuse_;
};

class CookTorranceMaterial final : public Material {
 public:
  CookTorranceMaterial(RoughnessParams rough, CtFresnel fresnel, RgbParam kd, RgbParam ks)
      : rough_(std::move(rough)), fresnel_(fresnel), kd_(std::move(kd)), ks_(std::move(ks)) {}
  const Bsdf* bsdf(const ShadingPoint& sp, ScratchArena& arena) const override {
    Rgb kd = kd_.eval(sp);
    Rgb ks = vmin(ks_.eval(sp), vmax(Rgb(1) - kd, Rgb(0)));
    return arena.make<CookTorranceBsdf>(rough_.at(sp), fresnel_, kd, ks);
  }

 private:
  RoughnessParams rough_;
  CtFresnel fresnel_;
  RgbParam kd_, ks_;
};

}  // namespace

void register_cook_torrance(MaterialRegistry& registry) {
  registry.add("cook_torrance", [](const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
    RoughnessParams rough = read_roughness(j, ptr, ctx, 0.3f, true);
    CtFresnel fresnel;
    std::string kind = params::string(j, "fresnel", ptr, "dielectric");
    if (kind == "conductor") {
      fresnel.conductor = true;
      ConductorIor ior = read_conductor_ior(j, ptr, "gold");
      fresnel.eta = ior.eta;
      fresnel.k = ior.k;
    } else if (kind != "dielectric") {
      throw SceneError(ptr + "/fresnel", "must be \"dielectric\" or \"conductor\"");
    } else {
      read_conductor_ior(j, ptr, "gold");  // validates "metal", "eta", "k" even when unused
    }
    fresnel.ior = params::number(j, "ior", ptr, 1.5f, 1.0f, 4.0f);
    RgbParam kd = params::rgb_param(j, "kd", ptr, Rgb(0), 0.0f, 1.0f, ctx);
    RgbParam ks = params::rgb_param(j, "ks", ptr, Rgb(1), 0.0f, 1.0f, ctx);
    if (!kd.texture && !ks.texture && max_component(kd.value + ks.value) > 1 + 1e-6f)
      throw SceneError(ptr + "/ks", "kd + ks must not exceed 1 in any channel (energy conservation)");
    return std::make_unique<CookTorranceMaterial>(std::move(rough), fresnel, std::move(kd), std::move(ks));
  });
}

}  // namespace tessera
