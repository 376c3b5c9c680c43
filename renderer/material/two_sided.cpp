// `two_sided`: wraps a material so that both sides of the surface show its front (+z) side. Opaque reflectors are
// already two-sided by the convention of bsdf.h; this matters for models whose back differs from their front (a
// dielectric seen from inside, a thin transmissive layer, a material built for one-sided glTF geometry).
#include "renderer/material/common.h"

namespace tessera {
namespace {

// Wraps a material so that both sides of the surface show its front (+z) side.
class TwoSidedBsdf final : public Bsdf {
 public:
  explicit TwoSidedBsdf(const Bsdf* inner) : inner_(inner) {}
  Rgb eval(const Vec3& wo, const Vec3& wi) const override {
    return wo.z < 0 ? inner_->eval(flip(wo), flip(wi)) : inner_->eval(wo, wi);
  }
  float pdf(const Vec3& wo, const Vec3& wi) const override {
    return wo.z < 0 ? inner_->pdf(flip(wo), flip(wi)) : inner_->pdf(wo, wi);
  }
  std::optional<BsdfSample> sample(const Vec3& wo, float uc, Vec2 u) const override {
    return sample_flipped(TransportMode::kRadiance, wo, uc, u);
  }
  Rgb eval_adjoint(const Vec3& wo, const Vec3& wi) const override {
    return wo.z < 0 ? inner_->eval_adjoint(flip(wo), flip(wi)) : inner_->eval_adjoint(wo, wi);
  }
  std::optional<BsdfSample> sample_adjoint(const Vec3& wo, float uc, Vec2 u) const override {
    return sample_flipped(TransportMode::kImportance, wo, uc, u);
  }
  uint32_t flags() const override { return inner_->flags(); }
  Rgb albedo_hint() const override { return inner_->albedo_hint(); }
  float roughness_hint() const override { return inner_->roughness_hint(); }
  Rgb eval_diffuse(const Vec3& wo, const Vec3& wi) const override {
    return wo.z < 0 ? inner_->eval_diffuse(flip(wo), flip(wi)) : inner_->eval_diffuse(wo, wi);
  }
  LobeColors lobe_colors() const override { return inner_->lobe_colors(); }

 private:
  static Vec3 flip(const Vec3& w) { return {w.x, w.y, -w.z}; }
  std::optional<BsdfSample> sample_flipped(TransportMode mode, const Vec3& wo, float uc, Vec2 u) const {
    if (wo.z >= 0) return inner_->sample_for(mode, wo, uc, u);
    std::optional<BsdfSample> s = inner_->sample_for(mode, flip(wo), uc, u);
    if (s) s->wi = flip(s->wi);
    return s;
  }
  const Bsdf* inner_;
};

class TwoSidedMaterial final : public Material {
 public:
  explicit TwoSidedMaterial(std::unique_ptr<Material> inner)
      : Material(Traits{.dispersive = inner->dispersive()}), inner_(std::move(inner)) {}
  const Bsdf* bsdf(const ShadingPoint& sp, ScratchArena& arena) const override {
    const Bsdf* inner = inner_->bsdf(sp, arena);
    return inner ? arena.make<TwoSidedBsdf>(inner) : nullptr;
  }

 private:
  std::unique_ptr<Material> inner_;
};

}  // namespace

void register_two_sided(MaterialRegistry& registry) {
  registry.add("two_sided", [](const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
    return std::make_unique<TwoSidedMaterial>(create_nested_material(j, "material", ptr, ctx, {{"type", "lambert"}}));
  });
}

}  // namespace tessera
