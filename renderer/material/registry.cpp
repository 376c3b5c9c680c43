#include <algorithm>
#include <cmath>
#include <filesystem>
#include <initializer_list>

#include "proto/asset_path.h"
#include "proto/did_you_mean.h"
#include "renderer/material/material.h"

#include "renderer/json_fields.h"
#include "renderer/scene_error.h"

namespace tessera {

void MaterialRegistry::add(const std::string& type, MaterialFactory factory) {
  factories_[type] = std::move(factory);
}

std::vector<std::string> MaterialRegistry::types() const {
  std::vector<std::string> out;
  for (const auto& [name, _] : factories_) out.push_back(name);
  return out;
}

const MaterialRegistry& MaterialRegistry::builtin() {
  static const MaterialRegistry registry = [] {
    MaterialRegistry r;
    register_builtin_materials(r);
    return r;
  }();
  return registry;
}

namespace {

// True when any of the parameters is a texture: textures (and nested materials) are objects; numbers, colours and
// names are not.
bool any_texture(const nlohmann::json& params) {
  return std::any_of(params.begin(), params.end(), [](const nlohmann::json& v) {
    return v.is_object() || (v.is_array() && std::any_of(v.begin(), v.end(), [](const nlohmann::json& e) {
                               return e.is_object() || e.is_array();
                             }));
  });
}

// The common keys of every model over `common` (the model's own): emission, a tangent-space normal map, and
// absorption inside a closed transmissive object given as the colour white light takes after
// "attenuation_distance" metres (as glTF's KHR_materials_volume).
void read_common_keys(const nlohmann::json& params, const std::string& pointer, const MaterialContext& ctx,
                      Material::Common& common) {
  if (params.contains("emission")) {
    common.emission = params::rgb_param(params, "emission", pointer, Rgb(0), 0.0f, 1e9f, ctx);
  }
  common.emission_one_sided = params::boolean(params, "one_sided", pointer, common.emission_one_sided);
  if (auto it = params.find("normal_map"); it != params.end()) {
    if (!it->is_object()) throw SceneError(pointer + "/normal_map", "must be a texture object");
    nlohmann::json map = *it;
    if (!map.contains("colorspace")) map["colorspace"] = "linear";
    nlohmann::json holder = {{"normal_map", map}};
    common.normal_map = params::rgb_param(holder, "normal_map", pointer, Rgb(1), 0.0f, 1.0f, ctx).texture;
  }
  common.normal_scale = params::number(params, "normal_scale", pointer, 1.0f, 0.0f, 10.0f);
  if (params.contains("attenuation_distance") || params.contains("attenuation_color")) {
    // A model that defines its interior (subsurface parameters) has no room for a second one.
    if (common.interior)
      throw SceneError(
          pointer + (params.contains("attenuation_color") ? "/attenuation_color" : "/attenuation_distance"),
          "this material's subsurface parameters define its interior medium: attenuation_color and "
          "attenuation_distance (an absorbing interior) cannot be given with them");
    const float distance = params::number(params, "attenuation_distance", pointer, 1.0f, 1e-6f, 1e9f);
    const Rgb color = params::rgb(params, "attenuation_color", pointer, Rgb(1), 1e-6f, 1.0f);
    const double rgb[3] = {color.x, color.y, color.z};
    common.interior = absorbing_medium(rgb, distance);
  }
}

// What the caller gave over `common`: each parameter it set (emission, coverage, a normal map, an interior) with
// the values that go with it.
void take_given(Material::Common given, const std::string& pointer, Material::Common& common) {
  if (!is_black(given.emission.value)) {
    common.emission = std::move(given.emission);
    common.emission_one_sided = given.emission_one_sided;
  }
  if (given.alpha_mode != Material::AlphaMode::kOpaque) {
    common.alpha_mode = given.alpha_mode;
    common.alpha_cutoff = given.alpha_cutoff;
    common.alpha = std::move(given.alpha);
  }
  if (given.normal_map) {
    common.normal_map = std::move(given.normal_map);
    common.normal_scale = given.normal_scale;
  }
  if (given.coat_normal_map) {
    common.coat_normal_map = std::move(given.coat_normal_map);
    common.coat_normal_scale = given.coat_normal_scale;
  }
  if (given.interior) {
    if (common.interior)
      throw SceneError(pointer,
                       "this material has an interior medium of its own (subsurface parameters or "
                       "attenuation_color and attenuation_distance): it cannot enclose another");
    common.interior = std::move(given.interior);
  }
}

}  // namespace

std::unique_ptr<Material> MaterialRegistry::create(const nlohmann::json& params, const std::string& pointer,
                                                   const MaterialContext& ctx, Material::Common given) const {
  if (!params.is_object()) throw SceneError(pointer, "a material must be an object");
  auto type_it = params.find("type");
  if (type_it == params.end() || !type_it->is_string())
    throw SceneError(pointer + "/type", "a material needs a \"type\" naming its model");
  auto it = factories_.find(type_it->get<std::string>());
  if (it == factories_.end()) {
    std::vector<std::string> known;
    for (const auto& [name, factory] : factories_) known.push_back(name);
    throw SceneError(pointer + "/type", "unknown material type \"" + type_it->get<std::string>() + "\"" +
                                            proto::did_you_mean(type_it->get<std::string>(), known));
  }
  std::unique_ptr<Material> material = it->second(params, pointer, ctx);
  read_common_keys(params, pointer, ctx, material->common_);
  take_given(std::move(given), pointer, material->common_);
  // Textures the caller gave count as the JSON's do: a glTF material whose only texture is a normal map still has
  // its hits' footprints worked out, for that map's filtering.
  const Material::Common& c = material->common_;
  material->traits_.reads_textures =
      any_texture(params) || c.normal_map || c.coat_normal_map || c.alpha.texture || c.emission.texture;
  return material;
}

namespace params {

namespace {
float checked_number(const nlohmann::json& v, const std::string& at, float min_value, float max_value) {
  if (!v.is_number()) throw SceneError(at, "must be a number");
  double d = v.get<double>();
  if (!std::isfinite(d)) throw SceneError(at, "must be finite");
  if (d < min_value || d > max_value) {
    throw SceneError(
        at, "must be between " + nlohmann::json(min_value).dump() + " and " + nlohmann::json(max_value).dump());
  }
  return static_cast<float>(d);
}
}  // namespace

float number(const nlohmann::json& obj, const std::string& key, const std::string& pointer, float fallback,
             float min_value, float max_value) {
  auto it = obj.find(key);
  if (it == obj.end()) return fallback;
  return checked_number(*it, pointer + "/" + json_pointer_token(key), min_value, max_value);
}

Rgb rgb(const nlohmann::json& obj, const std::string& key, const std::string& pointer, Rgb fallback, float min_value,
        float max_value) {
  auto it = obj.find(key);
  if (it == obj.end()) return fallback;
  const std::string at = pointer + "/" + json_pointer_token(key);
  if (it->is_number()) {
    float v = checked_number(*it, at, min_value, max_value);
    return Rgb(v);
  }
  if (!it->is_array() || it->size() != 3) throw SceneError(at, "must be a number or an array of 3 numbers");
  Rgb c;
  for (int i = 0; i < 3; ++i) c[i] = checked_number((*it)[i], at + "/" + std::to_string(i), min_value, max_value);
  return c;
}

namespace {

// Resolves a texture file named by a material inside the asset folder (proto/asset_path.h: relative, subfolders
// allowed, no "..", and the file, symlinks followed, inside the folder).
std::filesystem::path resolve_asset(const std::string& name, const std::string& at, const MaterialContext& ctx) {
  if (ctx.asset_root.empty()) throw SceneError(at, "file textures are not available here (no asset folder)");
  const proto::AssetPath file = proto::asset_path(name);
  if (!file.problem.empty()) throw SceneError(at, "\"" + name.substr(0, 200) + "\" is refused: " + file.problem);
  bool outside = false;
  auto full = proto::confined_file(ctx.asset_root, file.path, &outside);
  if (!full && outside) throw SceneError(at, "resolves outside the scene's folder");
  if (!full) throw SceneError(at, "no image file \"" + name + "\" in the scene's folder");
  return *full;
}

void check_keys(const nlohmann::json& obj, const std::string& at, std::initializer_list<const char*> allowed) {
  for (const auto& [key, _] : obj.items()) {
    bool ok = false;
    for (const char* a : allowed) ok = ok || key == a;
    if (!ok) throw SceneError(at + "/" + json_pointer_token(key), "unknown key \"" + key + "\"");
  }
}

// A texture object: {"texture": "file.png", "wrap": ..., "scale": [su, sv], ...} or {"checker": {"a", "b",
// "scale"}}. `factor` receives the constant the texture is multiplied with.
std::shared_ptr<const Texture> parse_texture(const nlohmann::json& v, const std::string& at, bool colour,
                                             float min_value, float max_value, const MaterialContext& ctx,
                                             Rgb* factor) {
  *factor = Rgb(1);
  if (v.contains("checker")) {
    check_keys(v, at, {"checker"});
    const nlohmann::json& c = v["checker"];
    const std::string cp = at + "/checker";
    if (!c.is_object()) throw SceneError(cp, "must be an object with \"a\", \"b\" and \"scale\"");
    check_keys(c, cp, {"a", "b", "scale", "uv"});
    Rgb a = rgb(c, "a", cp, Rgb(std::min(max_value, std::max(min_value, 0.8f))), min_value, max_value);
    Rgb b = rgb(c, "b", cp, Rgb(std::min(max_value, std::max(min_value, 0.2f))), min_value, max_value);
    if (!colour && (a.x != a.y || a.x != a.z)) throw SceneError(cp + "/a", "must be a number for this parameter");
    if (!colour && (b.x != b.y || b.x != b.z)) throw SceneError(cp + "/b", "must be a number for this parameter");
    float scale = number(c, "scale", cp, 8, 1e-6f, 1e6f);
    int uv_set = static_cast<int>(number(c, "uv", cp, 0, 0, 1));
    return make_checker_texture(a, b, scale, uv_set);
  }
  auto file_it = v.find("texture");
  if (file_it == v.end()) throw SceneError(at, "a texture object needs \"texture\" (an image file) or \"checker\"");
  check_keys(v, at,
             {"texture", "wrap", "wrap_t", "scale", "offset", "rotation", "channel", "colorspace", "uv", "factor"});
  const std::string fp = at + "/texture";
  if (!file_it->is_string()) throw SceneError(fp, "must be the relative path of an image file");
  // "#key" names an image held in memory (a glTF asset's embedded images); anything else is a file.
  const std::string name = file_it->get<std::string>();
  std::shared_ptr<const ImagePixels> embedded;
  std::filesystem::path file;
  if (!name.empty() && name[0] == '#') {
    auto img = ctx.images.find(name.substr(1));
    if (img == ctx.images.end()) throw SceneError(fp, "no embedded image \"" + name + "\"");
    embedded = img->second;
  } else {
    file = resolve_asset(name, fp, ctx);
  }
  TextureMapping mapping;
  auto wrap_mode = [&](const char* key) {
    std::string wrap = string(v, key, at, "repeat");
    if (wrap == "repeat") return WrapMode::kRepeat;
    if (wrap == "clamp") return WrapMode::kClamp;
    if (wrap == "mirror") return WrapMode::kMirror;
    throw SceneError(at + "/" + key, "must be \"repeat\", \"clamp\" or \"mirror\"");
  };
  mapping.wrap = wrap_mode("wrap");
  if (v.contains("wrap_t")) mapping.wrap_t = wrap_mode("wrap_t");
  mapping.rotation = number(v, "rotation", at, 0, -1000, 1000);
  auto read_vec2 = [&](const char* key, Vec2 fallback) {
    auto it = v.find(key);
    if (it == v.end()) return fallback;
    const std::string kp = at + "/" + key;
    auto num = [&](const nlohmann::json& n, const std::string& np) {
      if (!n.is_number() || !std::isfinite(n.get<double>()) || std::abs(n.get<double>()) > 1e6)
        throw SceneError(np, "must be a finite number");
      return static_cast<float>(n.get<double>());
    };
    if (it->is_number()) {
      float s = num(*it, kp);
      return Vec2(s, s);
    }
    if (!it->is_array() || it->size() != 2) throw SceneError(kp, "must be a number or an array of 2 numbers");
    return Vec2(num((*it)[0], kp + "/0"), num((*it)[1], kp + "/1"));
  };
  mapping.scale = read_vec2("scale", Vec2(1, 1));
  mapping.offset = read_vec2("offset", Vec2(0, 0));
  mapping.uv_set = static_cast<int>(number(v, "uv", at, 0, 0, 1));
  int channel = -1;
  if (v.contains("channel")) {
    const nlohmann::json& c = v["channel"];
    if (!c.is_number_integer() || c.get<int64_t>() < 0 || c.get<int64_t>() > 3)
      throw SceneError(at + "/channel", "must be 0, 1, 2 or 3");
    channel = static_cast<int>(c.get<int64_t>());
  } else if (!colour) {
    channel = 0;
  }
  std::string cs = string(v, "colorspace", at, colour ? "srgb" : "linear");
  if (cs != "srgb" && cs != "linear") throw SceneError(at + "/colorspace", "must be \"srgb\" or \"linear\"");
  *factor = rgb(v, "factor", at, Rgb(1), min_value, max_value);
  if (!colour && (factor->x != factor->y || factor->x != factor->z))
    throw SceneError(at + "/factor", "must be a number for this parameter");
  try {
    if (!embedded && ctx.headers_only) {
      check_image_file(file);
      embedded = stand_in_image();
    }
    if (embedded) return make_image_texture(embedded, cs == "srgb", channel, mapping);
    return make_image_texture(file, cs == "srgb", channel, mapping);
  } catch (const std::runtime_error& e) {
    throw SceneError(fp, e.what());
  }
}

}  // namespace

RgbParam rgb_param(const nlohmann::json& obj, const std::string& key, const std::string& pointer, Rgb fallback,
                   float min_value, float max_value, const MaterialContext& ctx) {
  RgbParam p;
  auto it = obj.find(key);
  if (it != obj.end() && it->is_object()) {
    p.texture = parse_texture(*it, pointer + "/" + json_pointer_token(key), true, min_value, max_value, ctx, &p.value);
    return p;
  }
  p.value = rgb(obj, key, pointer, fallback, min_value, max_value);
  return p;
}

FloatParam float_param(const nlohmann::json& obj, const std::string& key, const std::string& pointer, float fallback,
                       float min_value, float max_value, const MaterialContext& ctx) {
  FloatParam p;
  auto it = obj.find(key);
  if (it != obj.end() && it->is_object()) {
    Rgb factor;
    p.texture = parse_texture(*it, pointer + "/" + json_pointer_token(key), false, min_value, max_value, ctx, &factor);
    p.value = factor.x;
    return p;
  }
  p.value = number(obj, key, pointer, fallback, min_value, max_value);
  return p;
}

bool boolean(const nlohmann::json& obj, const std::string& key, const std::string& pointer, bool fallback) {
  return fields::boolean_key(obj, key, pointer, fallback);
}

std::string string(const nlohmann::json& obj, const std::string& key, const std::string& pointer,
                   const std::string& fallback) {
  auto it = obj.find(key);
  if (it == obj.end()) return fallback;
  if (!it->is_string()) throw SceneError(pointer + "/" + json_pointer_token(key), "must be a string");
  return it->get<std::string>();
}

}  // namespace params
}  // namespace tessera
