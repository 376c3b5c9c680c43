#include "renderer/cryptomatte.h"

#include <murmurhash.h>

#include <algorithm>
#include <cstdio>
#include <cstring>

#include <nlohmann/json.hpp>

namespace tessera::cryptomatte {

namespace {

std::string hex8(uint32_t v) {
  char text[9];
  std::snprintf(text, sizeof text, "%08x", v);
  return text;
}

}  // namespace

uint32_t hash(std::string_view name) {
  uint32_t out[1] = {0};
  lmmh_x86_32(name.data(), static_cast<unsigned>(name.size()), 0, out);
  return out[0];
}

uint32_t id_bits(uint32_t h) {
  // The specification's conversion: sign and mantissa kept, the exponent clamped to [1, 254].
  const uint32_t exponent = std::clamp<uint32_t>((h >> 23) & 0xffu, 1, 254);
  return (h & 0x807fffffu) | (exponent << 23);
}

float id_float(uint32_t bits) {
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

Ids ids_of(const std::vector<std::string>& object_names, const std::vector<std::string>& material_names) {
  Ids ids;
  auto add = [](const std::vector<std::string>& names, std::vector<uint32_t>& by_number,
                std::map<std::string, uint32_t>& manifest) {
    for (const std::string& full : names) {
      // A name is kept to kMaxNameBytes (cut before a UTF-8 continuation byte): an asset's names are not bounded,
      // and every name is in the manifest of each checkpoint and EXR.
      size_t length = std::min(full.size(), kMaxNameBytes);
      while (length > 0 && length < full.size() && (static_cast<unsigned char>(full[length]) & 0xc0) == 0x80) --length;
      const std::string name = full.substr(0, length);
      by_number.push_back(id_of(name));
      manifest.emplace(name, by_number.back());
    }
  };
  add(object_names, ids.object, ids.object_manifest);
  add(material_names, ids.material, ids.material_manifest);
  return ids;
}

std::vector<std::pair<std::string, std::string>> exr_metadata(std::string_view type_name,
                                                              const std::map<std::string, uint32_t>& manifest) {
  const std::string prefix = "cryptomatte/" + hex8(hash(type_name)).substr(0, 7) + "/";
  nlohmann::ordered_json names = nlohmann::ordered_json::object();
  for (const auto& [name, id] : manifest) names[name] = hex8(id);
  return {{prefix + "name", std::string(type_name)},
          {prefix + "hash", "MurmurHash3_32"},
          {prefix + "conversion", "uint32_to_float32"},
          {prefix + "manifest", names.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)}};
}

std::vector<std::string> channel_names(std::string_view type_name, int ranks) {
  std::vector<std::string> names;
  for (int layer = 0; 2 * layer < ranks; ++layer) {
    char number[3];
    std::snprintf(number, sizeof number, "%02d", layer % 100);
    for (const char* c : {"R", "G", "B", "A"}) names.push_back(std::string(type_name) + number + "." + c);
  }
  names.resize(static_cast<size_t>(2 * ranks));
  return names;
}

}  // namespace tessera::cryptomatte
