// Phong and Blinn-Phong (Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed., §2.5.4 "Shading Models").
//
// `phong`, `blinn_phong`: the energy-normalised, reciprocal ("modified") forms, usable for rendering:
//   Phong:       f = kd/pi + ks (n+2)/(2 pi) cos^n(alpha), alpha the angle between wi and the mirror direction of
//                wo (Lafortune & Willems 1994, "Using the modified Phong reflectance model for physically based
//                rendering", eq. 6);
//   Blinn-Phong: f = kd/pi + ks c(n) (N.H)^n (Dutré et al., §2.5.4 "Modified Blinn-Phong model", with the diffuse term
//                written as kd/pi and a normalisation c(n) chosen so that ks = 1 reflects everything at normal
//                incidence; see blinn_normalisation()).
// With kd + ks <= 1 (checked per channel for constants; textured values have ks clamped to 1 - kd) both conserve
// energy: each lobe's directional albedo is at most 1 and largest at normal incidence.
//
// `phong_classic`, `blinn_phong_classic`: the original forms (Dutré et al., §2.5.4), kept for comparison and teaching,
//   f = kd/pi + ks (R.Theta)^n / (N.Psi)   and   f = kd/pi + ks (N.H)^n / (N.Psi)
// with Psi = wi (towards the light). The 1/(N.Psi) makes them non-reciprocal and lets their albedo exceed 1
// (Dutré et al.: "It is not energy conserving, it does not satisfy Helmholtz's reciprocity"); their constant
// diffuse k_d is written kd/pi here so that kd is a reflectance in every model.
//
// Sampling: a diffuse (cosine) lobe and the specular lobe, chosen in proportion to the luminances of kd and ks;
// the Phong lobe is sampled around the mirror direction with pdf (n+1)/(2 pi) cos^n(alpha), the Blinn-Phong lobe
// through its half vector with pdf (n+1)/(2 pi) (N.H)^n / (4 wo.H) (Walter 2007, eq. 14). Directions that fall
// below the surface are discarded, so pdf integrates to less than 1 for wide lobes at grazing incidence.
#include "renderer/material/common.h"
#include "renderer/sampling.h"
#include "renderer/scene_error.h"

namespace tessera {
namespace {

enum class PhongVariant : uint8_t { kPhong, kBlinnPhong, kPhongClassic, kBlinnPhongClassic };

bool is_blinn(PhongVariant v) {
  return v == PhongVariant::kBlinnPhong || v == PhongVariant::kBlinnPhongClassic;
}

// c(n) with \int c (N.H)^n cos(theta_i) d(omega_i) = 1 for wo = N: there H bisects N and wi, theta_h = theta_i/2,
// and with c = cos(theta_h) the integral is 2 pi * 4 \int_{1/sqrt2}^1 c^{n+1} (2c^2 - 1) dc
// = 8 pi [2 (1 - 2^{-(n+4)/2}) / (n+4) - (1 - 2^{-(n+2)/2}) / (n+2)].
float blinn_normalisation(float n) {
  double a = 2 * (1 - std::pow(2.0, -(n + 4) / 2.0)) / (n + 4);
  double b = (1 - std::pow(2.0, -(n + 2) / 2.0)) / (n + 2);
  return static_cast<float>(1 / (8 * kPi * (a - b)));
}

class PhongBsdf final : public Bsdf {
 public:
  PhongBsdf(PhongVariant variant, Rgb kd, Rgb ks, float n, float norm)
      : variant_(variant),
        kd_(kd),
        ks_(ks),
        n_(n),
        norm_(norm),
        p_diffuse_(lobe_probability(luminance(kd), luminance(ks))) {}

  Rgb eval(const Vec3& wo_in, const Vec3& wi_in) const override {
    Vec3 wo = wo_in, wi = wi_in;
    if (!mirror_to_front(wo, wi)) return Rgb(0);
    return kd_ * kInvPi + ks_ * specular(wo, wi);
  }

  std::optional<BsdfSample> sample(const Vec3& wo_in, float uc, Vec2 u) const override {
    if (wo_in.z == 0) return std::nullopt;
    Vec3 wo = wo_in;
    const bool flip = wo.z < 0;
    if (flip) wo.z = -wo.z;
    Vec3 wi;
    const uint32_t lobe = uc < p_diffuse_ ? kBsdfDiffuse : kBsdfGlossy;
    if (uc < p_diffuse_) {
      wi = sample_cosine_hemisphere(u);
    } else if (is_blinn(variant_)) {
      Vec3 h = sample_power_cosine(u, n_);
      wi = h * (2 * dot(wo, h)) - wo;
    } else {
      wi = around(reflect_z(wo), sample_power_cosine(u, n_));
    }
    if (wi.z <= 0) return std::nullopt;
    float pdf = pdf_front(wo, wi);
    if (!(pdf > 0)) return std::nullopt;
    Rgb f = kd_ * kInvPi + ks_ * specular(wo, wi);
    if (flip) wi.z = -wi.z;
    return BsdfSample{f, wi, pdf, kBsdfReflection | lobe, 1.0f};
  }

  float pdf(const Vec3& wo_in, const Vec3& wi_in) const override {
    Vec3 wo = wo_in, wi = wi_in;
    if (!mirror_to_front(wo, wi)) return 0;
    return pdf_front(wo, wi);
  }

  uint32_t flags() const override { return kBsdfReflection | kBsdfGlossy | kBsdfDiffuse; }
  Rgb albedo_hint() const override { return kd_ + ks_; }
  // The Beckmann roughness of the same highlight, alpha = sqrt(2 / (n + 2)) (Walter et al. 2007, "Microfacet Models
  // for Refraction through Rough Surfaces", §5.2).
  float roughness_hint() const override { return std::sqrt(std::sqrt(2 / (n_ + 2))); }
  Rgb eval_diffuse(const Vec3& wo_in, const Vec3& wi_in) const override {
    Vec3 wo = wo_in, wi = wi_in;
    return mirror_to_front(wo, wi) ? kd_ * kInvPi : Rgb(0);
  }
  LobeColors lobe_colors() const override { return {kd_, ks_, Rgb(0)}; }

 private:
  static Vec3 reflect_z(const Vec3& w) { return {-w.x, -w.y, w.z}; }

  // The specular lobe's value (without ks) for wo, wi in the upper hemisphere.
  float specular(const Vec3& wo, const Vec3& wi) const {
    switch (variant_) {
      case PhongVariant::kPhong:
        return norm_ * std::pow(std::max(0.0f, dot(reflect_z(wo), wi)), n_);
      case PhongVariant::kPhongClassic:
        return std::pow(std::max(0.0f, dot(reflect_z(wo), wi)), n_) / wi.z;
      case PhongVariant::kBlinnPhong:
      case PhongVariant::kBlinnPhongClassic: {
        Vec3 h = normalize(wo + wi);
        float v = std::pow(std::max(0.0f, h.z), n_);
        return variant_ == PhongVariant::kBlinnPhong ? norm_ * v : v / wi.z;
      }
    }
    return 0;
  }

  float pdf_front(const Vec3& wo, const Vec3& wi) const {
    float spec;
    if (is_blinn(variant_)) {
      Vec3 h = normalize(wo + wi);
      float oh = dot(wo, h);
      spec = oh > 0 ? power_cosine_pdf(h.z, n_) / (4 * oh) : 0.0f;
    } else {
      spec = power_cosine_pdf(dot(reflect_z(wo), wi), n_);
    }
    return p_diffuse_ * cosine_hemisphere_pdf(wi.z) + (1 - p_diffuse_) * spec;
  }

  PhongVariant variant_;
  Rgb kd_, ks_;
  float n_, norm_;
  float p_diffuse_;
};

class PhongMaterial final : public Material {
 public:
  PhongMaterial(PhongVariant variant, RgbParam kd, RgbParam ks, float n)
      : variant_(variant), kd_(std::move(kd)), ks_(std::move(ks)), n_(n) {
    switch (variant) {
      case PhongVariant::kPhong:
        norm_ = (n + 2) * kInv2Pi;
        break;
      case PhongVariant::kBlinnPhong:
        norm_ = blinn_normalisation(n);
        break;
      default:
        norm_ = 1;
        break;
    }
  }
  const Bsdf* bsdf(const ShadingPoint& sp, ScratchArena& arena) const override {
    Rgb kd = kd_.eval(sp);
    Rgb ks = vmin(ks_.eval(sp), vmax(Rgb(1) - kd, Rgb(0)));
    return arena.make<PhongBsdf>(variant_, kd, ks, n_, norm_);
  }

 private:
  PhongVariant variant_;
  RgbParam kd_, ks_;
  float n_, norm_ = 1;
};

MaterialFactory phong_factory(PhongVariant variant) {
  return [variant](const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
    RgbParam kd = params::rgb_param(j, "kd", ptr, Rgb(0.5f), 0.0f, 1.0f, ctx);
    RgbParam ks = params::rgb_param(j, "ks", ptr, Rgb(0.3f), 0.0f, 1.0f, ctx);
    float n = params::number(j, "exponent", ptr, 32, 0, 100000);
    if (!kd.texture && !ks.texture && max_component(kd.value + ks.value) > 1 + 1e-6f)
      throw SceneError(ptr + "/ks", "kd + ks must not exceed 1 in any channel (energy conservation)");
    return std::make_unique<PhongMaterial>(variant, std::move(kd), std::move(ks), n);
  };
}

}  // namespace

Vec3 sample_power_cosine(Vec2 u, float exponent) {
  // Inverting the CDF of (n+1) cos^n(theta) sin(theta): cos(theta) = u^(1/(n+1)).
  float cos_theta = std::pow(u.x, 1 / (exponent + 1));
  float sin_theta = safe_sqrt(1 - cos_theta * cos_theta);
  float phi = 2 * kPi * u.y;
  return {sin_theta * std::cos(phi), sin_theta * std::sin(phi), cos_theta};
}

void register_phong(MaterialRegistry& registry) {
  registry.add("phong", phong_factory(PhongVariant::kPhong));
  registry.add("blinn_phong", phong_factory(PhongVariant::kBlinnPhong));
  registry.add("phong_classic", phong_factory(PhongVariant::kPhongClassic));
  registry.add("blinn_phong_classic", phong_factory(PhongVariant::kBlinnPhongClassic));
}

}  // namespace tessera
