// glTF materials (glTF 2.0, 3.9 and appendix B; the KHR_materials_* extensions) onto tessera's gltf_pbr model, with
// their textures, coverage, normal maps and volume absorption.
#include <algorithm>
#include <cmath>

#include "proto/did_you_mean.h"
#include "renderer/gltf/internal.h"
#include "renderer/material/material.h"

namespace tessera::gltf {

namespace {

// A glTF textureInfo as a tessera texture parameter: {"texture": "#image<i>", uv set, sampler wrap modes,
// KHR_texture_transform, channel, colour space, factor}. Null when the reference is unusable.
json texture_param(const json& doc, const json& info, int channel, bool srgb, const json& factor,
                   std::vector<std::string>* warnings) {
  if (!info.is_object() || !info.contains("index") || !info["index"].is_number_integer()) return nullptr;
  const int index = info["index"].get<int>();
  const json& textures = doc.contains("textures") ? doc["textures"] : json::array();
  if (index < 0 || index >= static_cast<int>(textures.size())) return nullptr;
  const json& tex = textures[index];
  int source = tex.value("source", -1);
  if (tex.contains("extensions") && !tex.contains("source")) {
    if (warnings) warnings->push_back("texture " + std::to_string(index) + " uses only an extension image source");
    return nullptr;
  }
  if (source < 0) return nullptr;
  json p = {
      {"texture", "#image" + std::to_string(source)}, {"factor", factor}, {"colorspace", srgb ? "srgb" : "linear"}};
  if (channel >= 0) p["channel"] = channel;
  int uv = info.value("texCoord", 0);
  auto wrap_name = [](int mode) {
    switch (mode) {
      case 33071:
        return "clamp";
      case 33648:
        return "mirror";
      default:
        return "repeat";
    }
  };
  if (tex.contains("sampler") && tex["sampler"].is_number_integer() && doc.contains("samplers")) {
    int si = tex["sampler"].get<int>();
    if (si >= 0 && si < static_cast<int>(doc["samplers"].size())) {
      const json& sampler = doc["samplers"][si];
      p["wrap"] = wrap_name(sampler.value("wrapS", 10497));
      p["wrap_t"] = wrap_name(sampler.value("wrapT", 10497));
    }
  }
  if (info.contains("extensions") && info["extensions"].contains("KHR_texture_transform")) {
    const json& t = info["extensions"]["KHR_texture_transform"];
    if (t.contains("offset")) p["offset"] = t["offset"];
    if (t.contains("scale")) p["scale"] = t["scale"];
    if (t.contains("rotation")) p["rotation"] = t["rotation"];
    if (t.contains("texCoord")) uv = t.value("texCoord", uv);
  }
  if (uv < 0 || uv > 1) {
    if (warnings) warnings->push_back("TEXCOORD_" + std::to_string(uv) + " is not supported; using TEXCOORD_0");
    uv = 0;
  }
  p["uv"] = uv;
  return p;
}

json number_or(const json& obj, const char* key, double fallback) {
  auto it = obj.find(key);
  return it != obj.end() && it->is_number() ? *it : json(fallback);
}
json rgb_or(const json& obj, const char* key, const json& fallback) {
  auto it = obj.find(key);
  return it != obj.end() && it->is_array() && it->size() >= 3 ? json{(*it)[0], (*it)[1], (*it)[2]} : fallback;
}

}  // namespace

json material_params(const json& doc, const json& m, std::vector<std::string>* warnings) {
  json p = {{"type", "gltf_pbr"}};
  const json pbr = m.value("pbrMetallicRoughness", json::object());
  const json ext = m.value("extensions", json::object());
  // A parameter that is a constant, or the texture scaled by that constant.
  auto set = [&](const char* key, const json& factor, const json& info, int channel, bool srgb) {
    json tex = texture_param(doc, info, channel, srgb, factor, warnings);
    p[key] = tex.is_null() ? factor : tex;
  };
  if (ext.contains("KHR_materials_unlit")) {
    // KHR_materials_unlit: the surface shows its base colour as it is, lit by nothing. A path tracer gives it that
    // radiance as emission on a surface that reflects nothing (black, no specular), so the camera sees the colour
    // exactly; as an emitter it also lights what is around it, which a viewer's unlit shading does not.
    p["base_color"] = json{0, 0, 0};
    p["metallic"] = 0.0;
    p["specular"] = 0.0;
    set("emission", rgb_or(pbr, "baseColorFactor", {1, 1, 1}), pbr.value("baseColorTexture", json()), -1, true);
    p["one_sided"] = !m.value("doubleSided", false);
    if (warnings)
      warnings->push_back("material \"" + m.value("name", std::string()) +
                          "\": KHR_materials_unlit is rendered as emission of its base colour (it lights its "
                          "surroundings too)");
    return p;
  }
  set("base_color", rgb_or(pbr, "baseColorFactor", {1, 1, 1}), pbr.value("baseColorTexture", json()), -1, true);
  const json mr = pbr.value("metallicRoughnessTexture", json());
  set("metallic", number_or(pbr, "metallicFactor", 1.0), mr, 2, false);
  set("roughness", number_or(pbr, "roughnessFactor", 1.0), mr, 1, false);
  double strength = 1;
  if (ext.contains("KHR_materials_emissive_strength"))
    strength = number_or(ext["KHR_materials_emissive_strength"], "emissiveStrength", 1.0).get<double>();
  json emissive = rgb_or(m, "emissiveFactor", {0, 0, 0});
  if (emissive[0].get<double>() > 0 || emissive[1].get<double>() > 0 || emissive[2].get<double>() > 0) {
    for (auto& c : emissive) c = c.get<double>() * strength;
    set("emission", emissive, m.value("emissiveTexture", json()), -1, true);
    p["one_sided"] = !m.value("doubleSided", false);
  }
  if (ext.contains("KHR_materials_ior")) p["ior"] = number_or(ext["KHR_materials_ior"], "ior", 1.5);
  if (ext.contains("KHR_materials_transmission")) {
    const json& t = ext["KHR_materials_transmission"];
    set("transmission", number_or(t, "transmissionFactor", 0.0), t.value("transmissionTexture", json()), 0, false);
  }
  // KHR_materials_volume: a thicknessFactor above 0 makes the object a solid dielectric (refracting in and out);
  // thickness 0, or no volume, keeps the surface thin-walled (the extension's "thin-walled" rule).
  if (ext.contains("KHR_materials_volume") && number_or(ext["KHR_materials_volume"], "thicknessFactor", 0.0) > 0)
    p["thin_walled"] = false;
  if (ext.contains("KHR_materials_dispersion")) {
    // KHR_materials_dispersion: 20 / V_d, which the extension defines for the volume of KHR_materials_volume; a thin
    // wall has no refraction to part colours.
    p["dispersion"] = number_or(ext["KHR_materials_dispersion"], "dispersion", 0.0);
    if (p["dispersion"].get<double>() > 0 && p.value("thin_walled", true) && warnings)
      warnings->push_back("material \"" + m.value("name", std::string()) +
                          "\": KHR_materials_dispersion has no effect without a KHR_materials_volume thickness "
                          "(the surface is thin-walled)");
  }
  if (ext.contains("KHR_materials_specular")) {
    const json& t = ext["KHR_materials_specular"];
    set("specular", number_or(t, "specularFactor", 1.0), t.value("specularTexture", json()), 3, false);
    set("specular_color", rgb_or(t, "specularColorFactor", {1, 1, 1}), t.value("specularColorTexture", json()), -1,
        true);
  }
  if (ext.contains("KHR_materials_clearcoat")) {
    const json& t = ext["KHR_materials_clearcoat"];
    set("clearcoat", number_or(t, "clearcoatFactor", 0.0), t.value("clearcoatTexture", json()), 0, false);
    set("clearcoat_roughness", number_or(t, "clearcoatRoughnessFactor", 0.0),
        t.value("clearcoatRoughnessTexture", json()), 1, false);
  }
  if (ext.contains("KHR_materials_sheen")) {
    const json& t = ext["KHR_materials_sheen"];
    set("sheen_color", rgb_or(t, "sheenColorFactor", {0, 0, 0}), t.value("sheenColorTexture", json()), -1, true);
    set("sheen_roughness", number_or(t, "sheenRoughnessFactor", 0.0), t.value("sheenRoughnessTexture", json()), 3,
        false);
  }
  if (ext.contains("KHR_materials_diffuse_transmission")) {
    // KHR_materials_diffuse_transmission: the factor (times the texture's A) and the colour (sRGB texture).
    const json& t = ext["KHR_materials_diffuse_transmission"];
    set("diffuse_transmission", number_or(t, "diffuseTransmissionFactor", 0.0),
        t.value("diffuseTransmissionTexture", json()), 3, false);
    set("diffuse_transmission_color", rgb_or(t, "diffuseTransmissionColorFactor", {1, 1, 1}),
        t.value("diffuseTransmissionColorTexture", json()), -1, true);
    if (p.value("thin_walled", true) == false && warnings)
      warnings->push_back("material \"" + m.value("name", std::string()) +
                          "\": KHR_materials_diffuse_transmission is not drawn on a refracting volume (thin-walled "
                          "only)");
  }
  if (ext.contains("KHR_materials_iridescence")) {
    // KHR_materials_iridescence: the factor (times the texture's R), the film's index, and its thickness in
    // nanometres, mix(minimum, maximum, the thickness texture's G), or the maximum without a texture.
    const json& t = ext["KHR_materials_iridescence"];
    set("iridescence", number_or(t, "iridescenceFactor", 0.0), t.value("iridescenceTexture", json()), 0, false);
    p["iridescence_ior"] = number_or(t, "iridescenceIor", 1.3);
    p["iridescence_thickness_minimum"] = number_or(t, "iridescenceThicknessMinimum", 100.0);
    p["iridescence_thickness_maximum"] = number_or(t, "iridescenceThicknessMaximum", 400.0);
    set("iridescence_thickness", 1.0, t.value("iridescenceThicknessTexture", json()), 1, false);
  }
  if (ext.contains("KHR_materials_anisotropy")) {
    // KHR_materials_anisotropy: strength (times the texture's B), rotation (radians, counter-clockwise from the
    // tangent) and the texture's RG direction in tangent space (linear).
    const json& t = ext["KHR_materials_anisotropy"];
    const json info = t.value("anisotropyTexture", json());
    set("anisotropy", number_or(t, "anisotropyStrength", 0.0), info, 2, false);
    p["anisotropy_rotation"] = number_or(t, "anisotropyRotation", 0.0);
    json dir = texture_param(doc, info, -1, false, json{1, 1, 1}, nullptr);
    if (!dir.is_null()) p["anisotropy_direction"] = dir;
  }
  return p;
}

namespace {

// KHR_materials_pbrSpecularGlossiness onto metallic-roughness, as the extension's own conversion example does
// (Khronos glTF repository, extensions/2.0/Archived/KHR_materials_pbrSpecularGlossiness, "convert-between-workflows"):
// metallic solved from the perceived brightness of diffuse and specular against a dielectric's 4 % reflectance, base
// colour blended between the diffuse and the specular colour by metallic squared, roughness = 1 - glossiness.
namespace specgloss {

constexpr double kDielectricSpecular = 0.04;

double perceived_brightness(const double c[3]) {
  return std::sqrt(0.299 * c[0] * c[0] + 0.587 * c[1] * c[1] + 0.114 * c[2] * c[2]);
}

double solve_metallic(double diffuse, double specular, double one_minus_specular_strength) {
  if (specular < kDielectricSpecular) return 0;
  const double a = kDielectricSpecular;
  const double b =
      diffuse * one_minus_specular_strength / (1 - kDielectricSpecular) + specular - 2 * kDielectricSpecular;
  const double c = kDielectricSpecular - specular;
  const double d = std::max(0.0, b * b - 4 * a * c);
  return std::clamp((-b + std::sqrt(d)) / (2 * a), 0.0, 1.0);
}

// Metallic, roughness and base colour of one diffuse, specular (linear RGB) and glossiness.
void convert(const double diffuse[3], const double specular[3], double glossiness, double* metallic, double* roughness,
             double base[3]) {
  const double one_minus = 1 - std::max({specular[0], specular[1], specular[2]});
  *metallic = solve_metallic(perceived_brightness(diffuse), perceived_brightness(specular), one_minus);
  *roughness = std::clamp(1 - glossiness, 0.0, 1.0);
  constexpr double kEpsilon = 1e-6;
  for (int c = 0; c < 3; ++c) {
    const double from_diffuse =
        diffuse[c] * (one_minus / (1 - kDielectricSpecular) / std::max(1 - *metallic, kEpsilon));
    const double from_specular =
        (specular[c] - kDielectricSpecular * (1 - *metallic)) * (1 / std::max(*metallic, kEpsilon));
    const double t = *metallic * *metallic;
    base[c] = std::clamp(from_diffuse + (from_specular - from_diffuse) * t, 0.0, 1.0);
  }
}

double srgb_to_linear(double v) {
  return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}

double linear_to_srgb(double v) {
  v = std::clamp(v, 0.0, 1.0);
  return v <= 0.0031308 ? v * 12.92 : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
}

}  // namespace specgloss

// The decoded pixels of the texture a textureInfo names, or null (no such texture, or its image not decoded).
std::shared_ptr<const ImagePixels> texture_pixels(
    const json& doc, const json& info, const std::map<std::string, std::shared_ptr<const ImagePixels>>& images) {
  if (!info.is_object() || !info.contains("index") || !info["index"].is_number_integer() || !doc.contains("textures") ||
      !doc["textures"].is_array())
    return nullptr;
  const int index = info["index"].get<int>();
  if (index < 0 || index >= static_cast<int>(doc["textures"].size())) return nullptr;
  const int source = doc["textures"][index].value("source", -1);
  auto it = images.find("image" + std::to_string(source));
  if (source < 0 || it == images.end() || !it->second || it->second->width <= 0 || it->second->height <= 0 ||
      it->second->channels <= 0)
    return nullptr;
  return it->second;
}

// The texel of `image` nearest to the centre of texel (x, y) of a width x height image over the same [0, 1]^2.
const uint8_t* nearest_texel(const ImagePixels& image, int x, int y, int width, int height) {
  const int ix = std::min(image.width - 1, static_cast<int>((x + 0.5) * image.width / width));
  const int iy = std::min(image.height - 1, static_cast<int>((y + 0.5) * image.height / height));
  return &image.data[(static_cast<size_t>(iy) * static_cast<size_t>(image.width) + static_cast<size_t>(ix)) *
                     static_cast<size_t>(image.channels)];
}

// Adds `pixels` to the document as a new image and texture (sampled as the texture `like` names is), and returns a
// textureInfo for it with `like`'s texCoord and transform.
json add_baked_texture(json& doc, std::map<std::string, std::shared_ptr<const ImagePixels>>& images,
                       std::shared_ptr<ImagePixels> pixels, const json& like) {
  if (!doc.contains("images") || !doc["images"].is_array()) doc["images"] = json::array();
  const size_t image = doc["images"].size();
  doc["images"].push_back(json::object());
  images["image" + std::to_string(image)] = std::move(pixels);
  json texture = {{"source", image}};
  const json& original = doc["textures"][like["index"].get<int>()];
  if (original.contains("sampler")) texture["sampler"] = original["sampler"];
  doc["textures"].push_back(texture);
  json info = like;
  info["index"] = doc["textures"].size() - 1;
  return info;
}

}  // namespace

json spec_gloss_to_metal_rough(json& doc, const json& material,
                               std::map<std::string, std::shared_ptr<const ImagePixels>>& images,
                               std::vector<std::string>* warnings) {
  const json& ext = material["extensions"]["KHR_materials_pbrSpecularGlossiness"];
  auto factor = [&](const char* key, int n, double fallback) {
    std::vector<double> v(static_cast<size_t>(n), fallback);
    if (ext.contains(key) && ext[key].is_array() && static_cast<int>(ext[key].size()) >= n)
      for (int i = 0; i < n; ++i) v[i] = ext[key][i].is_number() ? ext[key][i].get<double>() : fallback;
    else if (n == 1 && ext.contains(key) && ext[key].is_number())
      v[0] = ext[key].get<double>();
    return v;
  };
  const std::vector<double> diffuse = factor("diffuseFactor", 4, 1.0), specular = factor("specularFactor", 3, 1.0),
                            gloss = factor("glossinessFactor", 1, 1.0);
  double metallic, roughness, base[3];
  specgloss::convert(diffuse.data(), specular.data(), gloss[0], &metallic, &roughness, base);
  json out = material;
  out["extensions"].erase("KHR_materials_pbrSpecularGlossiness");
  json pbr = {{"baseColorFactor", {base[0], base[1], base[2], diffuse[3]}},
              {"metallicFactor", metallic},
              {"roughnessFactor", roughness}};
  // The diffuse texture alone: the base colour's, scaled by the factors' conversion (exact where metallic is 0).
  const json& diffuse_info = ext.value("diffuseTexture", json());
  if (diffuse_info.is_object()) {
    pbr["baseColorTexture"] = diffuse_info;
    for (int c = 0; c < 3; ++c)
      pbr["baseColorFactor"][c] = diffuse[c] > 0 ? std::clamp(base[c] / diffuse[c], 0.0, 1.0) : 0.0;
  }
  // A specular-glossiness texture: the conversion per texel, from that texel's specular and glossiness and the
  // diffuse colour at the same place (the diffuse texture's where it has one, read nearest at the texel's centre),
  // into two images of the larger texture's size: a metallic-roughness image (G roughness, B metallic, as glTF's) and,
  // as a metal's colour is its specular colour, a base colour image (sRGB, the diffuse alpha kept). The diffuse
  // texture is read so only where it maps as the specular one does (the same texCoord and transform); otherwise it
  // is the base colour as above and the diffuse factor enters the metalness.
  const std::shared_ptr<const ImagePixels> spec_image =
      texture_pixels(doc, ext.value("specularGlossinessTexture", json()), images);
  if (spec_image) {
    const json& info = ext["specularGlossinessTexture"];
    std::shared_ptr<const ImagePixels> diffuse_image = texture_pixels(doc, diffuse_info, images);
    if (diffuse_image && (diffuse_info.value("texCoord", 0) != info.value("texCoord", 0) ||
                          diffuse_info.value("extensions", json()) != info.value("extensions", json())))
      diffuse_image = nullptr;
    const ImagePixels& sg = *spec_image;
    const int width = diffuse_image ? std::max(sg.width, diffuse_image->width) : sg.width;
    const int height = diffuse_image ? std::max(sg.height, diffuse_image->height) : sg.height;
    auto metal_rough = std::make_shared<ImagePixels>();
    auto base_colour = std::make_shared<ImagePixels>();
    for (ImagePixels* out_image : {metal_rough.get(), base_colour.get()}) {
      out_image->width = width;
      out_image->height = height;
      out_image->channels = 4;
      out_image->data.resize(static_cast<size_t>(width) * static_cast<size_t>(height) * 4);
    }
    for (int y = 0; y < height; ++y) {
      for (int x = 0; x < width; ++x) {
        const uint8_t* p = nearest_texel(sg, x, y, width, height);
        double spec[3], diff[4] = {diffuse[0], diffuse[1], diffuse[2], diffuse[3]};
        for (int c = 0; c < 3; ++c)
          spec[c] = specgloss::srgb_to_linear(p[sg.channels >= 3 ? c : 0] / 255.0) * specular[c];
        const double g = (sg.channels == 4 || sg.channels == 2 ? p[sg.channels - 1] / 255.0 : 1.0) * gloss[0];
        if (diffuse_image) {
          const ImagePixels& d = *diffuse_image;
          const uint8_t* q = nearest_texel(d, x, y, width, height);
          for (int c = 0; c < 3; ++c) diff[c] *= specgloss::srgb_to_linear(q[d.channels >= 3 ? c : 0] / 255.0);
          if (d.channels == 4 || d.channels == 2) diff[3] *= q[d.channels - 1] / 255.0;
        }
        double m, r, b[3];
        specgloss::convert(diff, spec, g, &m, &r, b);
        const size_t at = (static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x)) * 4;
        uint8_t* o = &metal_rough->data[at];
        o[0] = 0;
        o[1] = static_cast<uint8_t>(std::lround(r * 255));
        o[2] = static_cast<uint8_t>(std::lround(m * 255));
        o[3] = 255;
        uint8_t* bc = &base_colour->data[at];
        for (int c = 0; c < 3; ++c) bc[c] = static_cast<uint8_t>(std::lround(specgloss::linear_to_srgb(b[c]) * 255));
        bc[3] = static_cast<uint8_t>(std::lround(std::clamp(diff[3], 0.0, 1.0) * 255));
      }
    }
    pbr["metallicRoughnessTexture"] = add_baked_texture(doc, images, std::move(metal_rough), info);
    pbr["metallicFactor"] = 1.0;
    pbr["roughnessFactor"] = 1.0;
    if (diffuse_image || !diffuse_info.is_object()) {
      pbr["baseColorTexture"] = add_baked_texture(doc, images, std::move(base_colour), info);
      pbr["baseColorFactor"] = {1.0, 1.0, 1.0, 1.0};
    }
  }
  out["pbrMetallicRoughness"] = pbr;
  if (warnings)
    warnings->push_back("material \"" + material.value("name", std::string()) +
                        "\": KHR_materials_pbrSpecularGlossiness is approximated by metallic-roughness (Khronos' "
                        "conversion, per texel where it is textured)");
  return out;
}

namespace {

// The common parameters of glTF material `m` (its JSON `mj`) that tessera's material JSON has no keys for: coverage,
// the normal maps and the volume's absorption (MaterialRegistry::create takes them).
Material::Common common_parameters(const json& doc, const json& mj, const tinygltf::Material& m,
                                   const std::string& pointer, const MaterialContext& mctx,
                                   std::vector<std::string>* warnings) {
  Material::Common common;
  // Coverage (spec 3.9.4): base colour alpha (factor times texture alpha); MASK against alphaCutoff, BLEND
  // stochastically.
  if (m.alphaMode == "MASK" || m.alphaMode == "BLEND") {
    common.alpha_mode = m.alphaMode == "MASK" ? Material::AlphaMode::kMask : Material::AlphaMode::kBlend;
    common.alpha_cutoff = static_cast<float>(m.alphaCutoff);
    const json pbr = mj.value("pbrMetallicRoughness", json::object());
    double a = pbr.contains("baseColorFactor") && pbr["baseColorFactor"].size() == 4
                   ? pbr["baseColorFactor"][3].get<double>()
                   : 1.0;
    json tex = texture_param(doc, pbr.value("baseColorTexture", json()), 3, false, std::clamp(a, 0.0, 1.0), nullptr);
    json holder = {{"alpha", tex.is_null() ? json(std::clamp(a, 0.0, 1.0)) : tex}};
    common.alpha = params::float_param(holder, "alpha", pointer, 1.0f, 0.0f, 1.0f, mctx);
  }
  // Normal map (spec 3.9.3): tangent-space, linear, scaled in x and y.
  if (mj.contains("normalTexture")) {
    json tex = texture_param(doc, mj["normalTexture"], -1, false, json{1, 1, 1}, warnings);
    if (!tex.is_null()) {
      json holder = {{"normal", tex}};
      common.normal_map = params::rgb_param(holder, "normal", pointer, Rgb(1), 0.0f, 1.0f, mctx).texture;
      common.normal_scale = static_cast<float>(mj["normalTexture"].value("scale", 1.0));
    }
  }
  // KHR_materials_clearcoat's clearcoatNormalTexture: the coat's own normal map, read like normalTexture.
  if (const json ext_cc = parse_extensions(m.extensions_json_string).value("KHR_materials_clearcoat", json());
      ext_cc.is_object() && ext_cc.contains("clearcoatNormalTexture")) {
    json tex = texture_param(doc, ext_cc["clearcoatNormalTexture"], -1, false, json{1, 1, 1}, warnings);
    if (!tex.is_null()) {
      json holder = {{"normal", tex}};
      common.coat_normal_map = params::rgb_param(holder, "normal", pointer, Rgb(1), 0.0f, 1.0f, mctx).texture;
      common.coat_normal_scale = static_cast<float>(ext_cc["clearcoatNormalTexture"].value("scale", 1.0));
    }
  }
  // KHR_materials_volume: absorption through the object (thickness is a rasteriser's stand-in; a path tracer
  // measures the real distance travelled inside the geometry).
  json ext = parse_extensions(m.extensions_json_string);
  if (ext.contains("KHR_materials_volume")) {
    const json& v = ext["KHR_materials_volume"];
    double distance = v.value("attenuationDistance", 0.0);
    json color = v.value("attenuationColor", json{1, 1, 1});
    if (color.is_array() && color.size() == 3) {
      double rgb[3];
      for (int c = 0; c < 3; ++c) rgb[c] = color[c].is_number() ? color[c].get<double>() : 1.0;
      common.interior = absorbing_medium(rgb, distance);
    }
  }
  return common;
}

}  // namespace

Materials make_materials(Import& import, std::map<std::string, std::shared_ptr<const ImagePixels>> images) {
  json& doc = import.doc;
  const tinygltf::Model& model = import.model;
  const std::string& pointer = import.pointer;
  Scene& scene = import.scene;
  MaterialContext mctx;
  mctx.images = std::move(images);
  Materials out;
  const MaterialRegistry& registry = MaterialRegistry::builtin();
  const json no_materials = json::array();
  const json& gltf_materials =
      doc.contains("materials") && doc["materials"].is_array() ? doc["materials"] : no_materials;
  std::vector<uint32_t>& material_index = out.index;
  material_index.resize(model.materials.size());
  for (size_t i = 0; i < model.materials.size(); ++i) {
    import.check_stop();
    const tinygltf::Material& m = model.materials[i];
    if (auto it = import.options.material_overrides.find(m.name);
        !m.name.empty() && it != import.options.material_overrides.end()) {
      material_index[i] = it->second;
      continue;
    }
    json mj = i < gltf_materials.size() && gltf_materials[i].is_object() ? gltf_materials[i] : json::object();
    if (mj.contains("extensions") && mj["extensions"].is_object() &&
        mj["extensions"].contains("KHR_materials_pbrSpecularGlossiness") &&
        mj["extensions"]["KHR_materials_pbrSpecularGlossiness"].is_object())
      mj = spec_gloss_to_metal_rough(doc, mj, mctx.images, &import.result.warnings);
    json params = material_params(doc, mj, &import.result.warnings);
    if (!registry.has("gltf_pbr")) {
      // Without the metallic-roughness model, keep colour and emission on a diffuse surface.
      json lambert = {{"type", "lambert"}, {"albedo", params.value("base_color", json{0.8, 0.8, 0.8})}};
      for (const char* key : {"emission", "one_sided"})
        if (params.contains(key)) lambert[key] = params[key];
      params = lambert;
    }
    material_index[i] = static_cast<uint32_t>(scene.materials.size());
    const std::string mp = pointer + "/materials/" + std::to_string(i);
    Material::Common common = common_parameters(doc, mj, m, mp, mctx, &import.result.warnings);
    scene.materials.push_back(registry.create(params, mp, mctx, std::move(common)));
    scene.material_names.push_back(m.name.empty() ? "gltf:" + std::to_string(i) : m.name);
  }
  return out;
}

// The glTF default material (spec 3.9.6): white, fully rough, and metallic 1 by the spec's defaults.
uint32_t Materials::default_material(Import& import) {
  if (default_index == kNoLight) {
    const MaterialRegistry& registry = MaterialRegistry::builtin();
    json params = registry.has("gltf_pbr")
                      ? json{{"type", "gltf_pbr"}, {"base_color", {1, 1, 1}}, {"metallic", 1.0}, {"roughness", 1.0}}
                      : json{{"type", "lambert"}, {"albedo", {1, 1, 1}}};
    default_index = static_cast<uint32_t>(import.scene.materials.size());
    import.scene.materials.push_back(registry.create(params, import.pointer, MaterialContext{}));
    import.scene.material_names.push_back("gltf:default");
  }
  return default_index;
}

// KHR_materials_variants (the extension's specification): the asset's variants are named in its root extension; a
// primitive's mappings give, for some variants, another material than its own. Choosing a variant sets every mapped
// primitive's material; an asset without variants, or a name it does not have, is an error at the variant's pointer.
void apply_variant(Import& import) {
  const std::string& name = import.options.variant;
  if (name.empty()) return;
  const std::string& at = import.options.variant_pointer.empty() ? import.pointer : import.options.variant_pointer;
  const json root = import.doc.contains("extensions") && import.doc["extensions"].is_object() ? import.doc["extensions"]
                                                                                              : json::object();
  std::vector<std::string> names;
  if (root.contains("KHR_materials_variants") && root["KHR_materials_variants"].is_object())
    for (const json& v : root["KHR_materials_variants"].value("variants", json::array()))
      names.push_back(v.is_object() && v.contains("name") && v["name"].is_string() ? v["name"].get<std::string>() : "");
  if (names.empty()) throw SceneError(at, "the glTF asset has no KHR_materials_variants variants");
  const auto it = std::find(names.begin(), names.end(), name);
  if (it == names.end()) {
    std::string known;
    for (const std::string& n : names) known += (known.empty() ? "\"" : ", \"") + n + "\"";
    throw SceneError(at, "the glTF asset has no variant \"" + name + "\"" + proto::did_you_mean(name, names) +
                             "; its variants: " + known);
  }
  const int variant = static_cast<int>(it - names.begin());
  for (tinygltf::Mesh& mesh : import.model.meshes)
    for (tinygltf::Primitive& prim : mesh.primitives) {
      const json ext = parse_extensions(prim.extensions_json_string);
      if (!ext.contains("KHR_materials_variants") || !ext["KHR_materials_variants"].is_object()) continue;
      for (const json& mapping : ext["KHR_materials_variants"].value("mappings", json::array())) {
        if (!mapping.is_object() || !mapping.contains("material") || !mapping["material"].is_number_integer()) continue;
        const json variants = mapping.value("variants", json::array());
        if (std::find(variants.begin(), variants.end(), json(variant)) == variants.end()) continue;
        const int material = mapping["material"].get<int>();
        if (material < 0 || material >= static_cast<int>(import.model.materials.size()))
          import.fail("a KHR_materials_variants mapping names material " + std::to_string(material) +
                      ", which does not exist");
        prim.material = material;
      }
    }
}

}  // namespace tessera::gltf
