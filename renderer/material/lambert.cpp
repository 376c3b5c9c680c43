// Lambert's ideal diffuse reflector, f_r = rho / pi (Dutré, Bala & Bekaert, Advanced Global Illumination, 2nd ed.,
// §2.5.3), sampled by cos(theta) / pi.
#include "renderer/material/material.h"
#include "renderer/sampling.h"

namespace tessera {
namespace {

class LambertBsdf final : public Bsdf {
 public:
  explicit LambertBsdf(Rgb rho) : rho_(rho) {}
  Rgb eval(const Vec3& wo, const Vec3& wi) const override { return same_hemisphere(wo, wi) ? rho_ * kInvPi : Rgb(0); }
  std::optional<BsdfSample> sample(const Vec3& wo, float, Vec2 u) const override {
    if (wo.z == 0) return std::nullopt;
    Vec3 wi = sample_cosine_hemisphere(u);
    if (wo.z < 0) wi.z = -wi.z;
    float pdf = cosine_hemisphere_pdf(std::abs(wi.z));
    if (pdf <= 0) return std::nullopt;
    return BsdfSample{rho_ * kInvPi, wi, pdf, kBsdfReflection | kBsdfDiffuse, 1.0f};
  }
  float pdf(const Vec3& wo, const Vec3& wi) const override {
    return same_hemisphere(wo, wi) ? cosine_hemisphere_pdf(std::abs(wi.z)) : 0.0f;
  }
  uint32_t flags() const override { return kBsdfReflection | kBsdfDiffuse | kBsdfOneLobe; }
  Rgb albedo_hint() const override { return rho_; }

 private:
  Rgb rho_;
};

class LambertMaterial final : public Material {
 public:
  explicit LambertMaterial(RgbParam albedo) : Material(Traits{.isotropic = true}), albedo_(std::move(albedo)) {}
  const Bsdf* bsdf(const ShadingPoint& sp, ScratchArena& arena) const override {
    return arena.make<LambertBsdf>(albedo_.eval(sp));
  }

 private:
  RgbParam albedo_;
};

// A surface that only emits: it absorbs all light that reaches it.
class EmissionMaterial final : public Material {
 public:
  explicit EmissionMaterial(RgbParam radiance) : Material(Traits{}, Common{.emission = std::move(radiance)}) {}
  const Bsdf* bsdf(const ShadingPoint&, ScratchArena&) const override { return nullptr; }
};

}  // namespace

void register_lambert(MaterialRegistry& registry) {
  registry.add("lambert", [](const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
    return std::make_unique<LambertMaterial>(params::rgb_param(j, "albedo", ptr, Rgb(0.8f), 0.0f, 1.0f, ctx));
  });
  registry.add("emission", [](const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
    // "radiance" is the emission model's own name for the common "emission" key.
    return std::make_unique<EmissionMaterial>(params::rgb_param(j, "radiance", ptr, Rgb(1.0f), 0.0f, 1e9f, ctx));
  });
}

}  // namespace tessera
