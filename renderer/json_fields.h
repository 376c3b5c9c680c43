// Reading the fields of a document: JSON pointers to them, and numbers checked as every document's numbers are
// (finite, within a range), raising SceneError at the field's pointer. Shared by the scene loader and the render
// settings' mapping (render_settings.h).
#pragma once

#include <cmath>
#include <string>

#include <nlohmann/json.hpp>

#include "renderer/scene_error.h"

namespace tessera::fields {

// The pointer of `key` (or element `index`) of the object (array) at `pointer`.
inline std::string at(const std::string& pointer, const std::string& key) {
  return pointer + "/" + json_pointer_token(key);
}
inline std::string at(const std::string& pointer, size_t index) {
  return pointer + "/" + std::to_string(index);
}

// A number no further than 1e30 from zero.
inline double finite_number(const nlohmann::json& v, const std::string& pointer) {
  if (!v.is_number()) throw SceneError(pointer, "must be a number");
  double d = v.get<double>();
  if (!std::isfinite(d) || std::abs(d) > 1e30) throw SceneError(pointer, "must be a finite number");
  return d;
}

// obj[key] within [lo, hi] (lo itself refused when `lo_exclusive`), as a float; `fallback` when absent.
inline float number_key(const nlohmann::json& obj, const std::string& key, const std::string& pointer, float fallback,
                        double lo, double hi, bool lo_exclusive = false) {
  auto it = obj.find(key);
  if (it == obj.end()) return fallback;
  double d = finite_number(*it, at(pointer, key));
  if (d < lo || d > hi || (lo_exclusive && d == lo)) {
    throw SceneError(at(pointer, key), std::string("must be ") + (lo_exclusive ? "greater than " : "at least ") +
                                           nlohmann::json(lo).dump() + " and at most " + nlohmann::json(hi).dump());
  }
  return static_cast<float>(d);
}

// obj[key], which must be true or false; `fallback` when absent.
inline bool boolean_key(const nlohmann::json& obj, const std::string& key, const std::string& pointer, bool fallback) {
  auto it = obj.find(key);
  if (it == obj.end()) return fallback;
  if (!it->is_boolean()) throw SceneError(at(pointer, key), "must be true or false");
  return it->get<bool>();
}

}  // namespace tessera::fields
