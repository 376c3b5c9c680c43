// Dielectric interfaces (glass, water): smooth and rough reflection + refraction, and thin panes.
//
// Smooth (Pharr, Jakob & Humphreys, Physically Based Rendering, 3rd ed., §8.2.4):
//   f_r = F / |cos| delta(reflect),  f_t = (1 - F) / |cos| delta(refract),
// F the exact unpolarised Fresnel reflectance (fresnel.h) with total internal reflection past the critical angle,
// directions by the law of reflection and Snell's law (Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed.,
// §2.5.3). Radiance crossing the interface changes by the square of the ratio of indices (Dutré et al., §2.5.3
// "Reciprocity for transparent surfaces": the ray density changes by (eta_2/eta_1)^2), so the radiance BTDF carries
// 1/eta'^2 with eta' = eta_(wi side) / eta_(wo side), and BsdfSample::eta = eta' lets the integrator take that factor
// out of Russian roulette.
//
// Rough: the microfacet interface of Walter et al. 2007 (rough_dielectric.h), its reflected and transmitted parts
// tinted by "reflectance" and "transmittance".
//
// Local frame: +z points outside; "ior" is eta_inside / eta_outside.
#include "renderer/bsdf/fresnel.h"
#include "renderer/bsdf/rough_dielectric.h"
#include "renderer/material/common.h"
#include "renderer/material/subsurface.h"
#include "renderer/scene_error.h"
#include "renderer/spectrum.h"

namespace tessera {

bool RoughDielectric::half_vector(const Vec3& wo, const Vec3& wi, Vec3* wm, float* etap) const {
  const float cos_o = wo.z, cos_i = wi.z;
  if (cos_o == 0 || cos_i == 0) return false;
  const bool reflect = cos_o * cos_i > 0;
  *etap = reflect ? 1.0f : (cos_o > 0 ? eta : 1 / eta);
  Vec3 m = wi * *etap + wo;
  float len2 = length_squared(m);
  if (!(len2 > 0)) return false;
  m = m / std::sqrt(len2);
  if (m.z < 0) m = -m;
  // Microfacets seen from behind by either direction contribute nothing.
  if (dot(m, wi) * cos_i <= 0 || dot(m, wo) * cos_o <= 0) return false;
  *wm = m;
  return true;
}

float RoughDielectric::eval(const Vec3& wo, const Vec3& wi, bool* transmitted) const {
  *transmitted = wo.z * wi.z < 0;
  Vec3 wm;
  float etap;
  if (!half_vector(wo, wi, &wm, &etap)) return 0;
  const float cos_o = wo.z, cos_i = wi.z;
  const float F = fresnel_dielectric(dot(wo, wm), eta);
  const float dg = dist.d(wm) * dist.g(wo, wi, wm);
  if (!*transmitted) return dg * F / std::abs(4 * cos_i * cos_o);
  const float denom = sqr(dot(wi, wm) + dot(wo, wm) / etap) * cos_i * cos_o;
  return dg * (1 - F) * std::abs(dot(wi, wm) * dot(wo, wm) / denom) / sqr(etap);
}

float RoughDielectric::pdf(const Vec3& wo, const Vec3& wi) const {
  Vec3 wm;
  float etap;
  if (!half_vector(wo, wi, &wm, &etap)) return 0;
  const float R = fresnel_dielectric(dot(wo, wm), eta);
  const float pr = R * weight_r, pt = (1 - R) * weight_t;
  if (pr + pt <= 0) return 0;
  const float dvis = dist.d_visible(wo, wm);
  if (wo.z * wi.z > 0) return dvis / (4 * std::abs(dot(wo, wm))) * pr / (pr + pt);
  const float dwm_dwi = std::abs(dot(wi, wm)) / sqr(dot(wi, wm) + dot(wo, wm) / etap);
  return dvis * dwm_dwi * pt / (pr + pt);
}

bool RoughDielectric::sample(const Vec3& wo, float uc, Vec2 u, Vec3* wi, bool* transmitted, float* etap) const {
  if (wo.z == 0) return false;
  // Visible normal of wo (from below: of the flipped configuration), on the upper side.
  const Vec3 wm = dist.sample_visible(wo.z > 0 ? wo : -wo, u, uc);
  const float om = dot(wo, wm);
  const float R = fresnel_dielectric(om, eta);
  const float pr = R * weight_r, pt = (1 - R) * weight_t;
  if (pr + pt <= 0) return false;
  if (uc * (pr + pt) < pr) {
    *wi = wm * (2 * om) - wo;
    *transmitted = false;
    *etap = 1;
    return wi->z * wo.z > 0;
  }
  if (!refract(wo, om > 0 ? wm : -wm, om > 0 ? eta : 1 / eta, wi)) return false;
  *transmitted = true;
  *etap = wo.z > 0 ? eta : 1 / eta;
  return wi->z * wo.z < 0;
}

namespace {

// An index-matched interface (ior 1) keeps the formulas finite by a hair's difference.
float keep_refracting(float ior) {
  return ior == 1.0f ? 1.0001f : ior;
}

class DielectricBsdf final : public Bsdf {
 public:
  DielectricBsdf(const MicrofacetDistribution& dist, float eta, const Rgb& reflectance, const Rgb& transmittance)
      : lobe_{dist, eta, max_component(reflectance), max_component(transmittance)},
        eta_(eta),
        kr_(reflectance),
        kt_(transmittance) {}

  Rgb eval(const Vec3& wo, const Vec3& wi) const override {
    if (smooth()) return Rgb(0);
    bool transmitted;
    const float f = lobe_.eval(wo, wi, &transmitted);
    return (transmitted ? kt_ : kr_) * f;
  }

  std::optional<BsdfSample> sample(const Vec3& wo, float uc, Vec2 u) const override {
    if (wo.z == 0) return std::nullopt;
    const float etap_t = wo.z > 0 ? eta_ : 1 / eta_;
    if (smooth()) {
      const float R = fresnel_dielectric(wo.z, eta_);
      const float pr = R * max_component(kr_), pt = (1 - R) * max_component(kt_);
      if (pr + pt <= 0) return std::nullopt;
      if (uc * (pr + pt) < pr) {
        Vec3 wi = reflect_local(wo);
        return BsdfSample{kr_ * (R / std::abs(wi.z)), wi, pr / (pr + pt), kBsdfReflection | kBsdfSpecular, 1.0f};
      }
      Vec3 wi;
      if (!refract(wo, Vec3(0, 0, wo.z > 0 ? 1.0f : -1.0f), etap_t, &wi)) return std::nullopt;
      Rgb f = kt_ * ((1 - R) / std::abs(wi.z) / sqr(etap_t));
      return BsdfSample{f, wi, pt / (pr + pt), kBsdfTransmission | kBsdfSpecular, etap_t};
    }
    Vec3 wi;
    bool transmitted;
    float etap;
    if (!lobe_.sample(wo, uc, u, &wi, &transmitted, &etap)) return std::nullopt;
    float pdf_value = pdf(wo, wi);
    Rgb f = eval(wo, wi);
    if (!(pdf_value > 0) || is_black(f)) return std::nullopt;
    return BsdfSample{f, wi, pdf_value, (transmitted ? kBsdfTransmission : kBsdfReflection) | kBsdfGlossy, etap};
  }

  float pdf(const Vec3& wo, const Vec3& wi) const override { return smooth() ? 0 : lobe_.pdf(wo, wi); }

  // The adjoint: the radiance form's 1/eta'^2 of transmission taken out again (f*(wo, wi) = f(wi, wo)).
  Rgb eval_adjoint(const Vec3& wo, const Vec3& wi) const override {
    const Rgb f = eval(wo, wi);
    return wo.z * wi.z < 0 ? f * sqr(wo.z > 0 ? eta_ : 1 / eta_) : f;
  }
  std::optional<BsdfSample> sample_adjoint(const Vec3& wo, float uc, Vec2 u) const override {
    std::optional<BsdfSample> s = sample(wo, uc, u);
    if (s && (s->flags & kBsdfTransmission)) s->f *= sqr(s->eta);
    return s;
  }

  uint32_t flags() const override {
    return kBsdfReflection | kBsdfTransmission | (smooth() ? kBsdfSpecular : kBsdfGlossy);
  }
  Rgb albedo_hint() const override { return kt_; }
  float roughness_hint() const override { return lobe_.dist.roughness(); }
  LobeColors lobe_colors() const override { return {Rgb(0), kr_, kt_}; }

 private:
  bool smooth() const { return lobe_.dist.effectively_smooth(); }

  RoughDielectric lobe_;
  float eta_;
  Rgb kr_, kt_;
};

// A thin pane: two parallel smooth interfaces close together, light leaving in the direction it came (pbrt-v4,
// ThinDielectricBxDF): R' = R + T^2 R / (1 - R^2) sums the inter-reflections (a geometric series), T' = 1 - R'.
class ThinDielectricBsdf final : public Bsdf {
 public:
  ThinDielectricBsdf(float eta, const Rgb& kr, const Rgb& kt) : eta_(eta), kr_(kr), kt_(kt) {}
  Rgb eval(const Vec3&, const Vec3&) const override { return Rgb(0); }
  float pdf(const Vec3&, const Vec3&) const override { return 0; }
  std::optional<BsdfSample> sample(const Vec3& wo, float uc, Vec2) const override {
    if (wo.z == 0) return std::nullopt;
    float R = fresnel_dielectric(std::abs(wo.z), eta_), T = 1 - R;
    if (R < 1) {
      R += T * T * R / (1 - R * R);
      T = 1 - R;
    }
    const float pr = R * max_component(kr_), pt = T * max_component(kt_);
    if (pr + pt <= 0) return std::nullopt;
    if (uc * (pr + pt) < pr) {
      Vec3 wi = reflect_local(wo);
      return BsdfSample{kr_ * (R / std::abs(wi.z)), wi, pr / (pr + pt), kBsdfReflection | kBsdfSpecular, 1.0f};
    }
    Vec3 wi = -wo;
    return BsdfSample{kt_ * (T / std::abs(wi.z)), wi, pt / (pr + pt), kBsdfTransmission | kBsdfSpecular, 1.0f};
  }
  uint32_t flags() const override { return kBsdfReflection | kBsdfTransmission | kBsdfSpecular; }
  Rgb albedo_hint() const override { return kt_; }
  float roughness_hint() const override { return 0; }
  LobeColors lobe_colors() const override { return {Rgb(0), kr_, kt_}; }

 private:
  float eta_;
  Rgb kr_, kt_;
};

class DielectricMaterial final : public Material {
 public:
  DielectricMaterial(bool thin, RoughnessParams rough, float ior, float dispersion, RgbParam kr, RgbParam kt,
                     std::shared_ptr<const Medium> interior = nullptr)
      : Material(Traits{.dispersive = dispersion > 0}, Common{.interior = std::move(interior)}),
        thin_(thin),
        rough_(std::move(rough)),
        ior_(ior),
        dispersion_(dispersion),
        kr_(std::move(kr)),
        kt_(std::move(kt)) {}
  const Bsdf* bsdf(const ShadingPoint& sp, ScratchArena& arena) const override {
    if (thin_) return arena.make<ThinDielectricBsdf>(ior_, kr_.eval(sp), kt_.eval(sp));
    // Dispersion: the index at the path's wavelength (spectrum.h); without one (no wavelength drawn), at the d line.
    float eta = ior_;
    if (dispersive() && sp.wavelength_nm > 0)
      eta = keep_refracting(spectrum::dispersive_ior(ior_, dispersion_, sp.wavelength_nm));
    return arena.make<DielectricBsdf>(rough_.at(sp), eta, kr_.eval(sp), kt_.eval(sp));
  }

 private:
  bool thin_;
  RoughnessParams rough_;
  float ior_;
  float dispersion_;  // 20 / V_d (V_d the Abbe number), as glTF's KHR_materials_dispersion
  RgbParam kr_, kt_;
};

MaterialFactory dielectric_factory(bool thin) {
  return [thin](const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
    RoughnessParams rough;
    if (!thin) rough = read_roughness(j, ptr, ctx, 0.0f, false);
    const float ior = keep_refracting(params::number(j, "ior", ptr, 1.5f, 1.0f, 4.0f));
    // A thin pane refracts out as it refracted in: no colours part, and it has no dispersion to set.
    const float dispersion = thin ? 0.0f : params::number(j, "dispersion", ptr, 0.0f, 0.0f, 100.0f);
    RgbParam kr = params::rgb_param(j, "reflectance", ptr, Rgb(1), 0.0f, 1.0f, ctx);
    RgbParam kt = params::rgb_param(j, "transmittance", ptr, Rgb(1), 0.0f, 1.0f, ctx);
    return std::make_unique<DielectricMaterial>(thin, std::move(rough), ior, dispersion, std::move(kr), std::move(kt));
  };
}

// The `subsurface` material: the scattering medium of its subsurface parameters (subsurface.h) behind a dielectric
// boundary, smooth or rough as a `dielectric`'s, untinted; at ior 1 the boundary is index-matched, an `interface`
// (what the subsurface parameters are defined against: their slab reflects subsurface_color).
std::unique_ptr<Material> make_subsurface(const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
  const SubsurfaceParams sss = read_subsurface(j, ptr, false);
  const float ior = params::number(j, "ior", ptr, 1.5f, 1.0f, 4.0f);
  if (ior == 1) return make_interface_material(subsurface_medium(sss));
  RgbParam white;
  white.value = Rgb(1);
  return std::make_unique<DielectricMaterial>(false, read_roughness(j, ptr, ctx, 0.0f, false), keep_refracting(ior),
                                              0.0f, white, white, subsurface_medium(sss));
}

}  // namespace

void register_dielectric(MaterialRegistry& registry) {
  registry.add("dielectric", dielectric_factory(false));
  registry.add("thin_dielectric", dielectric_factory(true));
  registry.add("subsurface", make_subsurface);
}

}  // namespace tessera
