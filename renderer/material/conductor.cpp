// Conductors (metals): smooth and rough reflection with the Fresnel reflectance of a complex index of refraction
// eta + i k per RGB channel (fresnel.h), f = F(wo.h) D G / (4 cos cos) when rough (Walter 2007, eq. 20) and a
// mirror F / |cos| when smooth (Pharr, Jakob & Humphreys, Physically Based Rendering, 3rd ed., §8.2.2).
#include "renderer/material/common.h"
#include "renderer/bsdf/fresnel.h"
#include "renderer/scene_error.h"

namespace tessera {
namespace {

// Complex refractive indices at representative RGB wavelengths R = 650 nm, G = 550 nm, B = 450 nm, from measured
// data as tabulated by refractiveindex.info: Au, Ag, Cu from Johnson & Christy, Phys. Rev. B 6, 4370 (1972); Cr and
// Fe from Johnson & Christy, Phys. Rev. B 9, 5056 (1974); Al from Rakic, Appl. Opt. 34, 4755 (1995). Values as
// widely reproduced in real-time rendering tables at these wavelengths (4-5 significant digits).
struct Metal {
  const char* name;
  Rgb eta, k;
};
constexpr Metal kMetals[] = {
    {"gold", {0.18299f, 0.42108f, 1.37340f}, {3.42420f, 2.34590f, 1.77040f}},
    {"silver", {0.16262f, 0.14512f, 0.13550f}, {4.07280f, 3.19000f, 2.19970f}},
    {"copper", {0.27105f, 0.67693f, 1.31640f}, {3.60920f, 2.62480f, 2.29210f}},
    {"aluminium", {1.51960f, 0.96565f, 0.53124f}, {7.66350f, 6.45810f, 5.06990f}},
    {"chromium", {3.64000f, 2.90080f, 1.99060f}, {4.35110f, 4.23110f, 3.75050f}},
    {"iron", {2.91140f, 2.94970f, 2.58450f}, {3.08930f, 2.93180f, 2.76700f}},
};

class ConductorBsdf final : public Bsdf {
 public:
  ConductorBsdf(const MicrofacetDistribution& dist, const Rgb& eta, const Rgb& k, const Rgb& tint)
      : dist_(dist), eta_(eta), k_(k), tint_(tint) {}

  Rgb eval(const Vec3& wo_in, const Vec3& wi_in) const override {
    if (dist_.effectively_smooth()) return Rgb(0);
    Vec3 wo = wo_in, wi = wi_in, h;
    if (!mirror_to_front(wo, wi) || !reflection_half_vector(wo, wi, &h)) return Rgb(0);
    return tint_ * fresnel_conductor(dot(wo, h), eta_, k_) * microfacet_reflection_eval(dist_, wo, wi);
  }

  std::optional<BsdfSample> sample(const Vec3& wo_in, float uc, Vec2 u) const override {
    if (wo_in.z == 0) return std::nullopt;
    Vec3 wo = wo_in;
    const bool flip = wo.z < 0;
    if (flip) wo.z = -wo.z;
    if (dist_.effectively_smooth()) {
      Vec3 wi = reflect_local(wo);
      Rgb f = tint_ * fresnel_conductor(wo.z, eta_, k_) / wo.z;
      if (flip) wi.z = -wi.z;
      return BsdfSample{f, wi, 1.0f, kBsdfReflection | kBsdfSpecular, 1.0f};
    }
    Vec3 wi;
    if (!microfacet_reflection_sample(dist_, wo, u, uc, &wi)) return std::nullopt;
    float pdf = microfacet_reflection_pdf(dist_, wo, wi);
    if (!(pdf > 0)) return std::nullopt;
    Vec3 h = normalize(wo + wi);
    Rgb f = tint_ * fresnel_conductor(dot(wo, h), eta_, k_) * microfacet_reflection_eval(dist_, wo, wi);
    if (flip) wi.z = -wi.z;
    return BsdfSample{f, wi, pdf, kBsdfReflection | kBsdfGlossy, 1.0f};
  }

  float pdf(const Vec3& wo_in, const Vec3& wi_in) const override {
    if (dist_.effectively_smooth()) return 0;
    Vec3 wo = wo_in, wi = wi_in;
    if (!mirror_to_front(wo, wi)) return 0;
    return microfacet_reflection_pdf(dist_, wo, wi);
  }

  uint32_t flags() const override {
    return kBsdfReflection | (dist_.effectively_smooth() ? kBsdfSpecular : kBsdfGlossy);
  }
  Rgb albedo_hint() const override { return tint_ * fresnel_conductor(1, eta_, k_); }
  float roughness_hint() const override { return dist_.roughness(); }

 private:
  MicrofacetDistribution dist_;
  Rgb eta_, k_, tint_;
};

class ConductorMaterial final : public Material {
 public:
  ConductorMaterial(RoughnessParams rough, ConductorIor ior, RgbParam tint)
      : rough_(std::move(rough)), ior_(ior), tint_(std::move(tint)) {}
  const Bsdf* bsdf(const ShadingPoint& sp, ScratchArena& arena) const override {
    return arena.make<ConductorBsdf>(rough_.at(sp), ior_.eta, ior_.k, tint_.eval(sp));
  }

 private:
  RoughnessParams rough_;
  ConductorIor ior_;
  RgbParam tint_;
};

}  // namespace

std::vector<std::string> metal_names() {
  std::vector<std::string> out;
  for (const Metal& m : kMetals) out.push_back(m.name);
  return out;
}

ConductorIor read_conductor_ior(const nlohmann::json& j, const std::string& ptr, const std::string& default_metal) {
  std::string name = params::string(j, "metal", ptr, default_metal);
  const Metal* metal = nullptr;
  for (const Metal& m : kMetals) {
    if (name == m.name) metal = &m;
  }
  if (!metal) {
    std::string list;
    for (const Metal& m : kMetals) list += std::string(list.empty() ? "" : ", ") + m.name;
    throw SceneError(ptr + "/metal", "unknown metal \"" + name + "\"; known: " + list);
  }
  // "eta" and "k", when given, override the named metal's values.
  ConductorIor ior;
  ior.eta = params::rgb(j, "eta", ptr, metal->eta, 0.0f, 100.0f);
  ior.k = params::rgb(j, "k", ptr, metal->k, 0.0f, 100.0f);
  if (!(max_component(ior.eta) > 0) && !(max_component(ior.k) > 0))
    throw SceneError(ptr + "/eta", "eta and k must not both be zero");
  return ior;
}

void register_conductor(MaterialRegistry& registry) {
  registry.add("conductor", [](const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
    RoughnessParams rough = read_roughness(j, ptr, ctx, 0.0f, false);
    ConductorIor ior = read_conductor_ior(j, ptr, "gold");
    RgbParam tint = params::rgb_param(j, "tint", ptr, Rgb(1), 0.0f, 1.0f, ctx);
    return std::make_unique<ConductorMaterial>(std::move(rough), ior, std::move(tint));
  });
}

}  // namespace tessera
