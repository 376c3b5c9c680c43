#include "proto/contract.h"

#include <map>
#include <stdexcept>

namespace tessera::embedded {
const std::map<std::string, std::string_view>& proto();
}  // namespace tessera::embedded

namespace tessera::proto {

const SchemaSet& contract_schemas() {
  static const SchemaSet set = [] {
    SchemaSet s;
    const std::string prefix = "schemas/";
    for (const auto& [path, text] : embedded::proto()) {
      if (path.rfind(prefix, 0) != 0) continue;
      // The files are ours and checked by the tests; a parse error here is a build defect.
      s.add(path.substr(prefix.size()), nlohmann::json::parse(text));
    }
    return s;
  }();
  return set;
}

std::string_view openapi_json() {
  auto it = embedded::proto().find("openapi.json");
  if (it == embedded::proto().end()) throw std::logic_error("openapi.json is not embedded");
  return it->second;
}

std::optional<std::string_view> contract_file(const std::string& path) {
  auto it = embedded::proto().find(path);
  if (it == embedded::proto().end()) return std::nullopt;
  return it->second;
}

}  // namespace tessera::proto
