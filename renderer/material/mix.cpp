// A stochastic mix of two materials: f = (1 - w) f_a + w f_b, pdf = (1 - w) pdf_a + w pdf_b. Sampling picks b with
// probability w, so the mixture's pdf is exactly that sum; a sampled non-delta direction reports the mixture's f and
// pdf (so sample, eval and pdf agree), a delta lobe its own weight times the lobe's (pbrt-v4's MixMaterial chooses
// one material per hit instead; keeping both lets MIS see the whole mixture). Emission is the mix's own "emission".
#include "renderer/material/common.h"
#include "renderer/scene_error.h"

namespace tessera {
namespace {

// A surface that absorbs everything (a pure emitter mixed in).
class BlackBsdf final : public Bsdf {
 public:
  Rgb eval(const Vec3&, const Vec3&) const override { return Rgb(0); }
  std::optional<BsdfSample> sample(const Vec3&, float, Vec2) const override { return std::nullopt; }
  float pdf(const Vec3&, const Vec3&) const override { return 0; }
  uint32_t flags() const override { return kBsdfNone; }
  Rgb albedo_hint() const override { return Rgb(0); }
};

class MixBsdf final : public Bsdf {
 public:
  MixBsdf(const Bsdf* a, const Bsdf* b, float w) : a_(a), b_(b), w_(w) {}
  Rgb eval(const Vec3& wo, const Vec3& wi) const override {
    return a_->eval(wo, wi) * (1 - w_) + b_->eval(wo, wi) * w_;
  }
  float pdf(const Vec3& wo, const Vec3& wi) const override { return a_->pdf(wo, wi) * (1 - w_) + b_->pdf(wo, wi) * w_; }
  std::optional<BsdfSample> sample(const Vec3& wo, float uc, Vec2 u) const override {
    return sample_mixed(TransportMode::kRadiance, wo, uc, u);
  }
  Rgb eval_adjoint(const Vec3& wo, const Vec3& wi) const override {
    return a_->eval_adjoint(wo, wi) * (1 - w_) + b_->eval_adjoint(wo, wi) * w_;
  }
  std::optional<BsdfSample> sample_adjoint(const Vec3& wo, float uc, Vec2 u) const override {
    return sample_mixed(TransportMode::kImportance, wo, uc, u);
  }
  uint32_t flags() const override {
    // Choosing between two parts takes the lobe sample, even when each part has one lobe.
    if (w_ <= 0) return a_->flags();
    if (w_ >= 1) return b_->flags();
    return (a_->flags() | b_->flags()) & ~static_cast<uint32_t>(kBsdfOneLobe);
  }
  Rgb albedo_hint() const override { return a_->albedo_hint() * (1 - w_) + b_->albedo_hint() * w_; }
  float roughness_hint() const override { return a_->roughness_hint() * (1 - w_) + b_->roughness_hint() * w_; }
  Rgb eval_diffuse(const Vec3& wo, const Vec3& wi) const override {
    return a_->eval_diffuse(wo, wi) * (1 - w_) + b_->eval_diffuse(wo, wi) * w_;
  }
  LobeColors lobe_colors() const override {
    const LobeColors a = a_->lobe_colors(), b = b_->lobe_colors();
    return {a.diffuse * (1 - w_) + b.diffuse * w_, a.glossy * (1 - w_) + b.glossy * w_,
            a.transmission * (1 - w_) + b.transmission * w_};
  }

 private:
  std::optional<BsdfSample> sample_mixed(TransportMode mode, const Vec3& wo, float uc, Vec2 u) const {
    const bool pick_b = uc < w_;
    const float weight = pick_b ? w_ : 1 - w_;
    const float uc2 = clamp(pick_b ? uc / w_ : (uc - w_) / (1 - w_), 0.0f, 0.99999994f);
    std::optional<BsdfSample> s = (pick_b ? b_ : a_)->sample_for(mode, wo, uc2, u);
    if (!s) return std::nullopt;
    if (is_delta(s->flags)) {
      s->pdf *= weight;
      s->f *= weight;
      return s;
    }
    s->f = eval_for(mode, wo, s->wi);
    s->pdf = pdf(wo, s->wi);
    if (!(s->pdf > 0)) return std::nullopt;
    return s;
  }

  const Bsdf* a_;
  const Bsdf* b_;
  float w_;
};

const BlackBsdf kBlack;

class MixMaterial final : public Material {
 public:
  MixMaterial(std::unique_ptr<Material> a, std::unique_ptr<Material> b, FloatParam w)
      : Material(Traits{.dispersive = a->dispersive() || b->dispersive()}),
        a_(std::move(a)),
        b_(std::move(b)),
        w_(std::move(w)) {}
  const Bsdf* bsdf(const ShadingPoint& sp, ScratchArena& arena) const override {
    float w = clamp(w_.eval(sp), 0.0f, 1.0f);
    const Bsdf* a = a_->bsdf(sp, arena);
    const Bsdf* b = b_->bsdf(sp, arena);
    if (!a && !b) return nullptr;
    return arena.make<MixBsdf>(a ? a : &kBlack, b ? b : &kBlack, w);
  }

 private:
  std::unique_ptr<Material> a_, b_;
  FloatParam w_;
};

// Nested materials are created through the registry; a depth limit keeps hostile documents from exhausting the
// stack.
thread_local int g_nesting = 0;
constexpr int kMaxNesting = 16;

}  // namespace

std::unique_ptr<Material> create_nested_material(const nlohmann::json& j, const std::string& key,
                                                 const std::string& ptr, const MaterialContext& ctx,
                                                 const nlohmann::json& fallback) {
  const std::string at = ptr + "/" + key;
  if (g_nesting >= kMaxNesting) throw SceneError(at, "materials are nested too deeply");
  ++g_nesting;
  try {
    auto it = j.find(key);
    auto m = MaterialRegistry::builtin().create(it == j.end() ? fallback : *it, at, ctx);
    --g_nesting;
    return m;
  } catch (...) {
    --g_nesting;
    throw;
  }
}

void register_mix(MaterialRegistry& registry) {
  registry.add("mix", [](const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx) {
    auto a = create_nested_material(j, "a", ptr, ctx, {{"type", "lambert"}, {"albedo", 0.8}});
    auto b = create_nested_material(j, "b", ptr, ctx, {{"type", "lambert"}, {"albedo", 0.2}});
    FloatParam w = params::float_param(j, "weight", ptr, 0.5f, 0.0f, 1.0f, ctx);
    return std::make_unique<MixMaterial>(std::move(a), std::move(b), std::move(w));
  });
}

}  // namespace tessera
