// The `interface` material: a boundary between two media of the same index of refraction, which light crosses
// without turning, reflecting or losing anything (pbrt-v4's "interface" material; Pharr, Jakob and Humphreys,
// Physically Based Rendering, 4th ed., §11.4). It is not drawn: it only marks where a medium begins and ends. Its BSDF
// is the delta transmission straight on, f = delta(wi + wo) / |cos theta_i|; the path tracer steps through such
// surfaces without a bounce (Material::Traits::index_matched), the other integrators see a specular transmission.
#include "renderer/material/common.h"

namespace tessera {
namespace {

class PassThroughBsdf final : public Bsdf {
 public:
  Rgb eval(const Vec3&, const Vec3&) const override { return Rgb(0); }
  std::optional<BsdfSample> sample(const Vec3& wo, float, Vec2) const override {
    if (wo.z == 0) return std::nullopt;
    const Vec3 wi = -wo;
    return BsdfSample{Rgb(1.0f / std::abs(wi.z)), wi, 1.0f, kBsdfTransmission | kBsdfSpecular, 1.0f};
  }
  float pdf(const Vec3&, const Vec3&) const override { return 0; }
  uint32_t flags() const override { return kBsdfTransmission | kBsdfSpecular | kBsdfOneLobe; }
  Rgb albedo_hint() const override { return Rgb(1); }
  float roughness_hint() const override { return 0; }
};

class InterfaceMaterial final : public Material {
 public:
  explicit InterfaceMaterial(std::shared_ptr<const Medium> interior)
      : Material(Traits{.isotropic = true, .index_matched = true}, Common{.interior = std::move(interior)}) {}
  const Bsdf* bsdf(const ShadingPoint&, ScratchArena& arena) const override { return arena.make<PassThroughBsdf>(); }
};

}  // namespace

std::unique_ptr<Material> make_interface_material(std::shared_ptr<const Medium> interior) {
  return std::make_unique<InterfaceMaterial>(std::move(interior));
}

void register_interface(MaterialRegistry& registry) {
  registry.add("interface", [](const nlohmann::json&, const std::string&, const MaterialContext&) {
    return make_interface_material();
  });
}

}  // namespace tessera
