#include "server/jobs/materials_catalog.h"

#include <algorithm>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "proto/contract.h"

namespace tessera::server {

using nlohmann::json;

namespace {

// A copy of `schema` with every $ref replaced by what it names (merged with the keywords beside it).
json inline_refs(const proto::SchemaSet& set, const std::string& doc, const json& schema, int depth) {
  if (depth > 16) return schema;
  if (schema.is_array()) {
    json out = json::array();
    for (const json& s : schema) out.push_back(inline_refs(set, doc, s, depth + 1));
    return out;
  }
  if (!schema.is_object()) return schema;
  json out = json::object();
  std::string here = doc;
  if (auto it = schema.find("$ref"); it != schema.end() && it->is_string()) {
    std::string target_doc;
    if (const json* target = set.resolve(doc, it->get<std::string>(), &target_doc)) {
      out = inline_refs(set, target_doc, *target, depth + 1);
      if (!out.is_object()) out = json::object();
    }
  }
  for (const auto& [key, value] : schema.items()) {
    if (key == "$ref") continue;
    out[key] = (value.is_object() || value.is_array()) ? inline_refs(set, here, value, depth + 1) : value;
  }
  return out;
}

// The tightest numeric range any branch of a (ref-free) schema allows, for a slider or a hint.
void numeric_range(const json& schema, std::optional<double>* lo, std::optional<double>* hi) {
  if (!schema.is_object()) return;
  for (const char* key : {"minimum", "exclusiveMinimum"})
    if (auto it = schema.find(key); it != schema.end() && it->is_number())
      *lo = lo->has_value() ? std::min(**lo, it->get<double>()) : it->get<double>();
  for (const char* key : {"maximum", "exclusiveMaximum"})
    if (auto it = schema.find(key); it != schema.end() && it->is_number())
      *hi = hi->has_value() ? std::max(**hi, it->get<double>()) : it->get<double>();
  if (auto it = schema.find("items"); it != schema.end()) numeric_range(*it, lo, hi);
  for (const char* key : {"anyOf", "oneOf", "allOf"})
    if (auto it = schema.find(key); it != schema.end() && it->is_array())
      for (const json& s : *it) numeric_range(s, lo, hi);
}

json at_or_null(const json& v, const char* pointer) {
  const json::json_pointer p(pointer);
  return v.contains(p) ? v.at(p) : json();
}

// The names of the properties of the schema a $ref names (`ref`, resolved into the file `target_doc`) in the order
// the file lists them. nlohmann::json keeps an object's members sorted by name, so this reads the compiled-in file
// again (once: `files` keeps it), keeping its order: a client builds its form in the order the schema's author gave.
// Empty when the file is not the contract's (a SchemaSet of the tests'): the catalogue then keeps the names' order.
std::vector<std::string> property_order(const std::string& target_doc, const std::string& ref,
                                        std::map<std::string, nlohmann::ordered_json>* files) {
  const size_t hash = ref.find('#');
  if (hash == std::string::npos) return {};
  auto [it, added] = files->try_emplace(target_doc);
  if (added) {
    auto text = proto::contract_file("schemas/" + target_doc);
    if (text) it->second = nlohmann::ordered_json::parse(*text, nullptr, false);
  }
  const nlohmann::ordered_json& file = it->second;
  const nlohmann::ordered_json::json_pointer pointer(ref.substr(hash + 1));
  if (!file.is_object() || !file.contains(pointer)) return {};
  std::vector<std::string> names;
  const nlohmann::ordered_json& schema = file.at(pointer);
  if (auto p = schema.find("properties"); p != schema.end() && p->is_object())
    for (const auto& [name, value] : p->items()) names.push_back(name);
  return names;
}

}  // namespace

json describe_materials(const proto::SchemaSet& set) {
  json list = json::array();
  const std::string doc_name = "material.schema.json";
  const json* doc = set.document(doc_name);
  if (!doc) return {{"materials", list}};
  const json models = doc->value("allOf", json::array());
  std::map<std::string, nlohmann::ordered_json> files;
  for (const json& entry : models) {
    const json type = at_or_null(entry, "/if/properties/type/const");
    const json ref = at_or_null(entry, "/then/$ref");
    if (!type.is_string() || !ref.is_string()) continue;
    std::string model_doc;
    const json* model = set.resolve(doc_name, ref.get<std::string>(), &model_doc);
    if (!model) continue;
    json params = json::array();
    const json properties = model->value("properties", json::object());
    std::vector<std::string> names = property_order(model_doc, ref.get<std::string>(), &files);
    for (const auto& [name, raw] : properties.items())
      if (std::find(names.begin(), names.end(), name) == names.end()) names.push_back(name);
    for (const std::string& name : names) {
      if (name == "type" || !properties.contains(name)) continue;
      const json& raw = properties.at(name);
      const json schema = inline_refs(set, model_doc, raw, 0);
      json p = {{"name", name}, {"description", schema.value("description", "")}, {"schema", schema}};
      if (schema.contains("default")) p["default"] = schema["default"];
      std::optional<double> lo, hi;
      numeric_range(schema, &lo, &hi);
      if (lo) p["minimum"] = *lo;
      if (hi) p["maximum"] = *hi;
      params.push_back(std::move(p));
    }
    list.push_back({{"type", type},
                    {"title", model->value("title", type.get<std::string>())},
                    {"description", model->value("description", "")},
                    {"parameters", std::move(params)}});
  }
  return {{"materials", list}};
}

}  // namespace tessera::server
