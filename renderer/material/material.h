// Materials: created by type name from JSON through one registry; at a hit they build the BSDF of that point.
#pragma once

#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "renderer/arena.h"
#include "renderer/bsdf/bsdf.h"
#include "renderer/medium.h"
#include "renderer/texture.h"

namespace tessera {

// A material: its model's BSDF, the traits the renderer needs to know of the model, and the parameters every model
// has in common. Both are fixed when the material is made and only read afterwards: the model states its traits (and
// any common parameter it defines itself) to this class's constructor; MaterialRegistry::create fills in the rest.
class Material {
 public:
  // What the renderer needs to know of a model to prepare its hits and paths.
  struct Traits {
    // True when the BSDF looks the same under any rotation of the tangent frame about the normal: hits on a material
    // without a normal map then get a frame built from the normal alone, without deriving a tangent from the texture
    // coordinates. False is always correct.
    bool isotropic = false;
    // True when the BSDF depends on the wavelength the path carries (ShadingPoint::wavelength_nm): an index of
    // refraction that varies with it (dispersion, spectrum.h). The integrators then draw a wavelength for the pixel
    // sample and weight the paths through this material by it.
    bool dispersive = false;
    // True for a boundary between media of the same index of refraction that is not drawn (the `interface`
    // material): paths cross it straight on, changing medium, and the path tracer does not count the crossing as a
    // bounce.
    bool index_matched = false;
    // False when none of the material's parameters is a texture: hits on it skip working out the texture footprint.
    // MaterialRegistry::create works it out from the parameters (a model does not set it). True is always correct.
    bool reads_textures = true;
  };

  // Coverage (glTF alphaMode): opaque; masked where coverage < cutoff; or blended, where a ray passes through with
  // probability 1 - coverage (stochastic transparency, unbiased for a path tracer).
  enum class AlphaMode { kOpaque, kMask, kBlend };

  // The parameters of every model: a few models define some themselves (an emission model's radiance, a subsurface
  // model's interior); MaterialRegistry::create sets the others from the JSON's common keys and from what a loader
  // read elsewhere (a glTF material's coverage, normal maps and volume; an object's medium).
  // Every member has an initializer: a model names only those it sets (Common{.interior = ...}).
  struct Common {
    RgbParam emission{};              // radiance, W/(m^2 sr) per channel
    bool emission_one_sided = false;  // emit only to the side the geometric normal points to
    AlphaMode alpha_mode = AlphaMode::kOpaque;
    float alpha_cutoff = 0.5f;
    FloatParam alpha{1.0f, nullptr};  // coverage in [0, 1]
    // The medium this surface encloses (medium.h; null: none): light refracted in through the front side travels in
    // it until it leaves through a back side (glTF KHR_materials_volume; the JSON materials' attenuation_color).
    std::shared_ptr<const Medium> interior{};
    // Tangent-space normal map (glTF normalTexture: linear RGB, x and y scaled by normal_scale), applied to the
    // shading frame at every hit.
    std::shared_ptr<const Texture> normal_map{};
    float normal_scale = 1;
    // A coating layer's own tangent-space normal map (glTF KHR_materials_clearcoat's clearcoatNormalTexture), read
    // from the frame before normal_map bends it; hits get it as ShadingPoint::coat_normal.
    std::shared_ptr<const Texture> coat_normal_map{};
    float coat_normal_scale = 1;
  };

  virtual ~Material() = default;
  // The BSDF at `sp`, built in `arena`; nullptr for a surface that does not scatter (a pure emitter).
  virtual const Bsdf* bsdf(const ShadingPoint& sp, ScratchArena& arena) const = 0;

  // Emitted radiance towards `w` (world direction, away from the surface). Any material may emit.
  Rgb emitted(const ShadingPoint& sp, const Vec3& w) const {
    if (!emissive()) return {};
    if (common_.emission_one_sided && dot(w, sp.ng) <= 0) return {};
    return common_.emission.eval(sp);
  }
  bool emissive() const { return !is_black(common_.emission.value); }
  const RgbParam& emission() const { return common_.emission; }
  bool emission_one_sided() const { return common_.emission_one_sided; }

  AlphaMode alpha_mode() const { return common_.alpha_mode; }
  float alpha_cutoff() const { return common_.alpha_cutoff; }
  float coverage(const ShadingPoint& sp) const { return common_.alpha.eval(sp); }

  const Medium* interior() const { return common_.interior.get(); }
  const Texture* normal_map() const { return common_.normal_map.get(); }
  float normal_scale() const { return common_.normal_scale; }
  const Texture* coat_normal_map() const { return common_.coat_normal_map.get(); }
  float coat_normal_scale() const { return common_.coat_normal_scale; }

  bool isotropic() const { return traits_.isotropic; }
  bool dispersive() const { return traits_.dispersive; }
  bool index_matched() const { return traits_.index_matched; }
  bool reads_textures() const { return traits_.reads_textures; }

 protected:
  Material() = default;
  explicit Material(Traits traits) : traits_(traits) {}
  Material(Traits traits, Common common) : traits_(traits), common_(std::move(common)) {}

 private:
  friend class MaterialRegistry;  // create sets reads_textures and the common parameters the model leaves open
  Traits traits_;
  Common common_;
};

// Where texture files named by a material may come from.
struct MaterialContext {
  std::filesystem::path asset_root;  // empty: no file textures allowed
  // Images in memory that texture parameters may name as "#<key>" (a glTF asset's images, "#image3").
  std::map<std::string, std::shared_ptr<const ImagePixels>> images;
  // Image files are checked from their headers only, and textures over them are a 1x1 stand-in (validating a job at
  // submission: the scene is not rendered).
  bool headers_only = false;
};

// Makes a material from its JSON object; throws SceneError naming the field (`pointer` is the object's pointer).
using MaterialFactory = std::function<std::unique_ptr<Material>(
    const nlohmann::json& params, const std::string& pointer, const MaterialContext& ctx)>;

class MaterialRegistry {
 public:
  // The registry with every built-in model.
  static const MaterialRegistry& builtin();

  void add(const std::string& type, MaterialFactory factory);
  bool has(const std::string& type) const { return factories_.count(type) != 0; }
  std::vector<std::string> types() const;
  // Creates the material described by `params` (which holds "type"), with its common parameters: the model's own,
  // over them the JSON's common keys ("emission", "normal_map", "attenuation_color" ...), and over those what the
  // caller read elsewhere (`given`: a glTF material's coverage, normal maps and volume; an object's medium). A
  // material has one interior: a second one is refused.
  std::unique_ptr<Material> create(const nlohmann::json& params, const std::string& pointer, const MaterialContext& ctx,
                                   Material::Common given = {}) const;

 private:
  std::map<std::string, MaterialFactory> factories_;
};

// Adds every model the renderer ships to `registry` (one line per model in material_registry.cpp).
void register_builtin_materials(MaterialRegistry& registry);

// Helpers for factories: read a parameter, check its range, raise SceneError naming the field.
namespace params {
float number(const nlohmann::json& obj, const std::string& key, const std::string& pointer, float fallback,
             float min_value, float max_value);
Rgb rgb(const nlohmann::json& obj, const std::string& key, const std::string& pointer, Rgb fallback, float min_value,
        float max_value);
RgbParam rgb_param(const nlohmann::json& obj, const std::string& key, const std::string& pointer, Rgb fallback,
                   float min_value, float max_value, const MaterialContext& ctx);
FloatParam float_param(const nlohmann::json& obj, const std::string& key, const std::string& pointer, float fallback,
                       float min_value, float max_value, const MaterialContext& ctx);
bool boolean(const nlohmann::json& obj, const std::string& key, const std::string& pointer, bool fallback);
std::string string(const nlohmann::json& obj, const std::string& key, const std::string& pointer,
                   const std::string& fallback);
}  // namespace params

}  // namespace tessera
