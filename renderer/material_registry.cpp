#include <cmath>

#include "renderer/material.h"
#include "renderer/scene_error.h"

namespace tessera {

void MaterialRegistry::add(const std::string& type, MaterialFactory factory) { factories_[type] = std::move(factory); }

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

std::unique_ptr<Material> MaterialRegistry::create(const nlohmann::json& params, const std::string& pointer,
                                                   const MaterialContext& ctx) const {
  if (!params.is_object()) throw SceneError(pointer, "a material must be an object");
  auto type_it = params.find("type");
  if (type_it == params.end() || !type_it->is_string())
    throw SceneError(pointer + "/type", "a material needs a \"type\" naming its model");
  auto it = factories_.find(type_it->get<std::string>());
  if (it == factories_.end())
    throw SceneError(pointer + "/type", "unknown material type \"" + type_it->get<std::string>() + "\"");
  std::unique_ptr<Material> material = it->second(params, pointer, ctx);
  if (params.contains("emission")) {
    material->emission = params::rgb_param(params, "emission", pointer, Rgb(0), 0.0f, 1e9f, ctx);
  }
  material->emission_one_sided = params::boolean(params, "one_sided", pointer, material->emission_one_sided);
  return material;
}

namespace params {

namespace {
float checked_number(const nlohmann::json& v, const std::string& at, float min_value, float max_value) {
  if (!v.is_number()) throw SceneError(at, "must be a number");
  double d = v.get<double>();
  if (!std::isfinite(d)) throw SceneError(at, "must be finite");
  if (d < min_value || d > max_value) {
    throw SceneError(at, "must be between " + nlohmann::json(min_value).dump() + " and " +
                             nlohmann::json(max_value).dump());
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

RgbParam rgb_param(const nlohmann::json& obj, const std::string& key, const std::string& pointer, Rgb fallback,
                   float min_value, float max_value, const MaterialContext& /*ctx*/) {
  RgbParam p;
  p.value = rgb(obj, key, pointer, fallback, min_value, max_value);
  return p;
}

FloatParam float_param(const nlohmann::json& obj, const std::string& key, const std::string& pointer, float fallback,
                       float min_value, float max_value, const MaterialContext& /*ctx*/) {
  FloatParam p;
  p.value = number(obj, key, pointer, fallback, min_value, max_value);
  return p;
}

bool boolean(const nlohmann::json& obj, const std::string& key, const std::string& pointer, bool fallback) {
  auto it = obj.find(key);
  if (it == obj.end()) return fallback;
  if (!it->is_boolean()) throw SceneError(pointer + "/" + json_pointer_token(key), "must be true or false");
  return it->get<bool>();
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
