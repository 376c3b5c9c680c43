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

namespace {

// The strings of `node` down the tokens of `pattern` from `at`, onto `out` by pointer.
void find_refs(const nlohmann::json& node, std::string_view pattern, const std::string& at,
               std::vector<std::string>* out) {
  if (pattern.empty()) {
    if (node.is_string()) out->push_back(at);
    return;
  }
  const size_t end = pattern.find('/', 1);
  const std::string token(pattern.substr(1, end == std::string_view::npos ? std::string_view::npos : end - 1));
  const std::string_view rest = end == std::string_view::npos ? std::string_view() : pattern.substr(end);
  if (token == "*") {
    if (node.is_array())
      for (size_t i = 0; i < node.size(); ++i) find_refs(node[i], rest, at + "/" + std::to_string(i), out);
  } else if (node.is_object()) {
    if (auto it = node.find(token); it != node.end()) find_refs(*it, rest, at + "/" + token, out);
  }
}

}  // namespace

std::vector<std::string> asset_refs(const nlohmann::json& doc) {
  std::vector<std::string> out;
  for (std::string_view pattern : kAssetRefPointers) find_refs(doc, pattern, "", &out);
  return out;
}

}  // namespace tessera::proto
