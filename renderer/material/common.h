// Helpers shared by the material model files in renderer/material/: the two-sided reflector convention, lobe selection,
// and reading the parameters several models have in common (microfacet roughness, conductor indices).
#pragma once

#include <string>

#include "renderer/bsdf/microfacet.h"
#include "renderer/material/material.h"

namespace tessera {

// Opaque reflectors treat a back-side wo like a front-side one mirrored through the surface (bsdf.h): flips both
// directions so that wo.z > 0. Returns false when wi is then not in the upper hemisphere (no reflection).
inline bool mirror_to_front(Vec3& wo, Vec3& wi) {
  if (wo.z < 0) {
    wo.z = -wo.z;
    wi.z = -wi.z;
  }
  return wo.z > 0 && wi.z > 0;
}

// Probability of choosing the first of two lobes with (non-negative) weights a and b.
inline float lobe_probability(float a, float b) {
  return a + b > 0 ? a / (a + b) : 0.5f;
}

// A frame around direction w (for sampling lobes centred on a reflection direction).
inline Vec3 around(const Vec3& w, const Vec3& local) {
  return Frame::from_normal(w).to_world(local);
}
// cos^n lobe around +z: pdf (n + 1)/(2 pi) cos^n theta (Lafortune & Willems 1994, section 4).
Vec3 sample_power_cosine(Vec2 u, float exponent);
inline float power_cosine_pdf(float cos_theta, float exponent) {
  return cos_theta > 0 ? (exponent + 1) * kInv2Pi * std::pow(cos_theta, exponent) : 0.0f;
}

// The `interface` material (interface.cpp): an index-matched boundary that is not drawn, for models whose surface is
// one, enclosing `interior` (null: none).
std::unique_ptr<Material> make_interface_material(std::shared_ptr<const Medium> interior = nullptr);

// Roughness parameters of a microfacet model: "distribution" ("ggx" | "beckmann"), "roughness" (isotropic alpha)
// or "alpha_x" / "alpha_y" (anisotropic, along the tangent / bitangent), texture-able.
struct RoughnessParams {
  MicrofacetType type = MicrofacetType::kGgx;
  MaskingType masking = MaskingType::kSmith;
  FloatParam alpha_x, alpha_y;
  MicrofacetDistribution at(const ShadingPoint& sp) const {
    MicrofacetDistribution d;
    d.type = type;
    d.masking = masking;
    d.alpha_x = alpha_x.eval(sp);
    d.alpha_y = alpha_y.texture || alpha_y.value != alpha_x.value ? alpha_y.eval(sp) : d.alpha_x;
    // Keep the distribution well defined in the glossy range; below 1e-3 models switch to their smooth lobes.
    d.alpha_x = clamp(d.alpha_x, 0.0f, 4.0f);
    d.alpha_y = clamp(d.alpha_y, 0.0f, 4.0f);
    return d;
  }
};
RoughnessParams read_roughness(const nlohmann::json& j, const std::string& ptr, const MaterialContext& ctx,
                               float default_roughness, bool allow_v_cavity);

// Complex index of refraction of a conductor: "metal" (a named metal from the table in conductor.cpp) or
// "eta" and "k" per RGB channel.
struct ConductorIor {
  Rgb eta, k;
};
ConductorIor read_conductor_ior(const nlohmann::json& j, const std::string& ptr, const std::string& default_metal);
// Creates the material at j[key] (or `fallback` when absent) through the built-in registry, for models that wrap
// other materials; limits the nesting depth.
std::unique_ptr<Material> create_nested_material(const nlohmann::json& j, const std::string& key,
                                                 const std::string& ptr, const MaterialContext& ctx,
                                                 const nlohmann::json& fallback);

// The names of the tabulated metals, for the schema test.
std::vector<std::string> metal_names();

}  // namespace tessera
