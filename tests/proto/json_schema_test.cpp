// The schema validator against the real contract: valid documents pass, invalid ones fail at the right pointer.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>

#include "proto/contract.h"
#include "proto/did_you_mean.h"
#include "proto/json_schema.h"

namespace tessera::proto {
namespace {

using nlohmann::json;

json cornell_job() {
  std::ifstream in(std::filesystem::path(TESSERA_SOURCE_DIR) / "proto/examples/cornell.json");
  return json::parse(in);
}

std::optional<SchemaError> validate_job(const json& doc) {
  return contract_schemas().validate(doc, "job.schema.json");
}

TEST(JsonSchema, CornellExampleIsValid) {
  auto e = validate_job(cornell_job());
  EXPECT_FALSE(e) << e->pointer << ": " << e->message;
}

// Every job in proto/examples/ (the benchmark scenes among them) is valid as written.
TEST(JsonSchema, EveryExampleIsValid) {
  int checked = 0;
  for (const auto& entry :
       std::filesystem::directory_iterator(std::filesystem::path(TESSERA_SOURCE_DIR) / "proto/examples")) {
    if (entry.path().extension() != ".json") continue;
    std::ifstream in(entry.path());
    auto e = validate_job(json::parse(in));
    EXPECT_FALSE(e) << entry.path() << " " << e->pointer << ": " << e->message;
    ++checked;
  }
  EXPECT_GE(checked, 3);
}

TEST(JsonSchema, MaterialJobIsValid) {
  json doc = {{"kind", "material"}, {"material", {{"type", "lambert"}, {"albedo", 0.5}}}, {"render", {{"spp", 4}}}};
  EXPECT_FALSE(validate_job(doc));
}

struct Case {
  const char* name;
  const char* patch;  // JSON Patch (RFC 6902) applied to the Cornell job
  const char* pointer;
  const char* keyword;
};

class InvalidJob : public testing::TestWithParam<Case> {};

TEST_P(InvalidJob, FailsAtPointer) {
  const Case& c = GetParam();
  json doc = cornell_job().patch(json::parse(c.patch));
  auto e = validate_job(doc);
  ASSERT_TRUE(e) << "accepted";
  EXPECT_EQ(e->pointer, c.pointer) << e->message;
  EXPECT_EQ(e->keyword, c.keyword) << e->message;
  EXPECT_FALSE(e->message.empty());
}

const Case kCases[] = {
    {"width_zero", R"([{"op":"replace","path":"/render/width","value":0}])", "/render/width", "minimum"},
    {"width_string", R"([{"op":"replace","path":"/render/width","value":"NaN"}])", "/render/width", "type"},
    {"width_fraction", R"([{"op":"replace","path":"/render/width","value":64.5}])", "/render/width", "type"},
    {"spp_negative", R"([{"op":"replace","path":"/render/spp","value":-1}])", "/render/spp", "minimum"},
    {"huge_height", R"([{"op":"replace","path":"/render/height","value":1e300}])", "/render/height", "maximum"},
    {"bad_estimator", R"([{"op":"replace","path":"/render/estimator","value":"bdpt"}])", "/render/estimator", "enum"},
    {"bad_integrator", R"([{"op":"add","path":"/render/integrator","value":"photon_mapping"}])", "/render/integrator",
     "enum"},
    {"unknown_render_key", R"([{"op":"add","path":"/render/widht","value":3}])", "/render/widht",
     "additionalProperties"},
    {"missing_camera", R"([{"op":"remove","path":"/scene/camera"}])", "/scene/camera", "required"},
    {"missing_kind", R"([{"op":"remove","path":"/kind"}])", "/kind", "required"},
    {"unknown_shape", R"([{"op":"replace","path":"/scene/objects/2/shape","value":"cube"}])", "/scene/objects/2/shape",
     "enum"},
    {"sphere_without_radius",
     R"([{"op":"replace","path":"/scene/objects/0","value":{"shape":"sphere","material":"white","center":[0,0,0]}}])",
     "/scene/objects/0/radius", "required"},
    {"sphere_radius_zero",
     R"([{"op":"replace","path":"/scene/objects/0","value":{"shape":"sphere","material":"white","center":[0,0,0],"radius":0}}])",
     "/scene/objects/0/radius", "exclusiveMinimum"},
    {"rectangle_extra_key", R"([{"op":"add","path":"/scene/objects/0/radius","value":1}])", "/scene/objects/0/radius",
     "additionalProperties"},
    {"vec3_too_short", R"([{"op":"replace","path":"/scene/camera/from","value":[0,1]}])", "/scene/camera/from",
     "minItems"},
    {"coordinate_string", R"([{"op":"replace","path":"/scene/camera/to/1","value":"NaN"}])", "/scene/camera/to/1",
     "type"},
    {"fov_180", R"([{"op":"replace","path":"/scene/camera/fov_deg","value":180}])", "/scene/camera/fov_deg", "maximum"},
    {"negative_index", R"([{"op":"replace","path":"/scene/objects/6/indices/4","value":-2}])",
     "/scene/objects/6/indices/4", "minimum"},
    {"albedo_above_one", R"([{"op":"replace","path":"/scene/materials/red/albedo/0","value":1.5}])",
     "/scene/materials/red/albedo/0", "maximum"},
    {"material_unknown_type", R"([{"op":"replace","path":"/scene/materials/red/type","value":"velvet"}])",
     "/scene/materials/red/type", "enum"},
    {"material_unknown_param", R"([{"op":"add","path":"/scene/materials/red/radiance","value":1}])",
     "/scene/materials/red/radiance", "additionalProperties"},
    {"material_name_empty", R"([{"op":"add","path":"/scene/materials/","value":{"type":"lambert"}}])",
     "/scene/materials/", "minLength"},
    {"light_without_position", R"([{"op":"add","path":"/scene/lights","value":[{"type":"point"}]}])",
     "/scene/lights/0/position", "required"},
    {"outputs_unknown", R"([{"op":"replace","path":"/outputs/0","value":"jpg"}])", "/outputs/0", "enum"},
    {"outputs_empty", R"([{"op":"replace","path":"/outputs","value":[]}])", "/outputs", "minItems"},
    // 2^53 + 1, which a double reads as 2^53, the maximum.
    {"seed_above_2_53", R"([{"op":"add","path":"/render/seed","value":9007199254740993}])", "/render/seed", "maximum"},
    {"priority_too_high", R"([{"op":"add","path":"/priority","value":1000}])", "/priority", "maximum"},
    {"scene_missing", R"([{"op":"remove","path":"/scene"}])", "/scene", "required"},
};

INSTANTIATE_TEST_SUITE_P(Contract, InvalidJob, testing::ValuesIn(kCases),
                         [](const testing::TestParamInfo<Case>& info) { return std::string(info.param.name); });

TEST(JsonSchema, AlternativesReportTheBranchThatGotFurthest) {
  // Both branches of the rgb anyOf fail; the array branch failed deeper, at the element.
  json doc = cornell_job();
  doc["scene"]["materials"]["light"]["radiance"] = json::array({1, -1, 1});
  auto e = validate_job(doc);
  ASSERT_TRUE(e);
  EXPECT_EQ(e->pointer, "/scene/materials/light/radiance/1");
  EXPECT_EQ(e->keyword, "minimum");
  // Neither branch accepts a string: one message names both.
  doc["scene"]["materials"]["light"]["radiance"] = "bright";
  e = validate_job(doc);
  ASSERT_TRUE(e);
  EXPECT_EQ(e->pointer, "/scene/materials/light/radiance");
  EXPECT_EQ(e->message.rfind("must be a number or an array", 0), 0u) << e->message;
}

TEST(JsonSchema, NotAnObject) {
  auto e = validate_job(json::array({1, 2}));
  ASSERT_TRUE(e);
  EXPECT_EQ(e->pointer, "");
  EXPECT_EQ(e->keyword, "type");
}

TEST(JsonSchema, DeepInstancesAreRefused) {
  SchemaSet set;
  set.add("any.json", json::parse(R"({"items": {"$ref": "#"}})"));
  json deep = json::array();
  for (int i = 0; i < 100; ++i) deep = json::array({deep});
  auto e = set.validate(deep, "any.json", 64);
  ASSERT_TRUE(e);
  EXPECT_EQ(e->keyword, "depth");
}

TEST(JsonSchema, ReferenceCyclesEnd) {
  SchemaSet set;
  set.add("loop.json", json::parse(R"({"$ref": "#"})"));
  auto e = set.validate(json(1), "loop.json");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->keyword, "$ref");
}

TEST(JsonSchema, OneOfNeedsExactlyOne) {
  SchemaSet set;
  set.add("s.json", json::parse(R"({"oneOf": [{"type": "integer"}, {"minimum": 0}]})"));
  EXPECT_FALSE(set.validate(json(-3), "s.json"));
  EXPECT_FALSE(set.validate(json(2.5), "s.json"));
  EXPECT_TRUE(set.validate(json(3), "s.json"));     // both
  EXPECT_TRUE(set.validate(json(-2.5), "s.json"));  // neither
}

TEST(JsonSchema, IfThenElseAndPatternAndStrings) {
  SchemaSet set;
  set.add("s.json", json::parse(R"({"if": {"type": "string"}, "then": {"pattern": "^[a-f]+$", "maxLength": 3},
                                    "else": {"type": "null"}})"));
  EXPECT_FALSE(set.validate(json("abc"), "s.json"));
  EXPECT_TRUE(set.validate(json("abcd"), "s.json"));
  EXPECT_TRUE(set.validate(json("xyz"), "s.json"));
  EXPECT_FALSE(set.validate(json(nullptr), "s.json"));
  EXPECT_TRUE(set.validate(json(1), "s.json"));
  // Lengths count code points: three two-byte characters.
  set.add("len.json", json::parse(R"({"maxLength": 3})"));
  EXPECT_FALSE(set.validate(json("\u00e9\u00e9\u00e9"), "len.json"));
}

TEST(JsonSchema, NestingDepthOfText) {
  EXPECT_EQ(json_nesting_depth("{}"), 1u);
  EXPECT_EQ(json_nesting_depth(R"({"a": [[1], {"b": 2}]})"), 3u);
  EXPECT_EQ(json_nesting_depth(R"({"a": "[[[[\"[[["})"), 1u);  // brackets inside strings do not count
  EXPECT_EQ(json_nesting_depth(std::string(100000, '[')), 100000u);
  EXPECT_EQ(json_nesting_depth("12"), 0u);
}

// Every keyword in the contract is one this validator implements (or an annotation), so the server and a standard
// validator cannot disagree because a keyword was silently ignored.
void collect_keywords(const json& schema, std::set<std::string>* out);
void collect_keywords_in_map(const json& map, std::set<std::string>* out) {
  for (const auto& [_, s] : map.items()) collect_keywords(s, out);
}
void collect_keywords(const json& schema, std::set<std::string>* out) {
  if (!schema.is_object()) return;
  for (const auto& [k, v] : schema.items()) {
    out->insert(k);
    if (k == "properties" || k == "$defs")
      collect_keywords_in_map(v, out);
    else if (k == "allOf" || k == "anyOf" || k == "oneOf")
      for (const json& s : v) collect_keywords(s, out);
    else if (k == "items" || k == "additionalProperties" || k == "propertyNames" || k == "if" || k == "then" ||
             k == "else")
      collect_keywords(v, out);
  }
}

TEST(JsonSchema, ContractUsesOnlySupportedKeywords) {
  const std::set<std::string> supported = {"type",
                                           "enum",
                                           "const",
                                           "required",
                                           "properties",
                                           "additionalProperties",
                                           "propertyNames",
                                           "items",
                                           "minItems",
                                           "maxItems",
                                           "minimum",
                                           "maximum",
                                           "exclusiveMinimum",
                                           "exclusiveMaximum",
                                           "minLength",
                                           "maxLength",
                                           "pattern",
                                           "allOf",
                                           "anyOf",
                                           "oneOf",
                                           "if",
                                           "then",
                                           "else",
                                           "$ref",
                                           "$defs",
                                           "$id",
                                           "$schema",
                                           "title",
                                           "description",
                                           "default",
                                           "format",
                                           "examples"};
  ASSERT_GE(contract_schemas().documents().size(), 6u);
  for (const auto& [name, schema] : contract_schemas().documents()) {
    std::set<std::string> used;
    collect_keywords(schema, &used);
    for (const std::string& k : used) EXPECT_TRUE(supported.count(k)) << name << " uses unsupported keyword " << k;
  }
}

void check_refs(const SchemaSet& set, const std::string& doc, const json& v) {
  if (v.is_object()) {
    for (const auto& [k, sub] : v.items()) {
      if (k == "$ref" && sub.is_string()) {
        std::string target;
        EXPECT_NE(set.resolve(doc, sub.get<std::string>(), &target), nullptr) << doc << ": " << sub;
      } else {
        check_refs(set, doc, sub);
      }
    }
  } else if (v.is_array()) {
    for (const json& sub : v) check_refs(set, doc, sub);
  }
}

TEST(JsonSchema, EveryReferenceResolves) {
  for (const auto& [name, schema] : contract_schemas().documents()) check_refs(contract_schemas(), name, schema);
}

// The instance pointers where a job document can hold an asset reference, found by walking the schemas from
// job.schema.json ("*" for any key or index): they must be exactly kAssetRefPointers, which the command line and
// the daemon's multipart submissions rely on.
void collect_asset_refs(const std::string& doc, const json& schema, const std::string& at, int depth,
                        std::set<std::string>* out) {
  if (!schema.is_object() || depth > 24) return;
  if (auto it = schema.find("$ref"); it != schema.end()) {
    const std::string ref = it->get<std::string>();
    if (ref.size() >= 16 && ref.compare(ref.size() - 16, 16, "/$defs/asset_ref") == 0) {
      out->insert(at);
    } else {
      std::string target_doc;
      if (const json* target = contract_schemas().resolve(doc, ref, &target_doc))
        collect_asset_refs(target_doc, *target, at, depth + 1, out);
    }
  }
  if (auto it = schema.find("properties"); it != schema.end())
    for (const auto& [key, sub] : it->items()) collect_asset_refs(doc, sub, at + "/" + key, depth + 1, out);
  for (const char* key : {"items", "additionalProperties"})
    if (auto it = schema.find(key); it != schema.end()) collect_asset_refs(doc, *it, at + "/*", depth + 1, out);
  for (const char* key : {"allOf", "anyOf", "oneOf"})
    if (auto it = schema.find(key); it != schema.end())
      for (const json& sub : *it) collect_asset_refs(doc, sub, at, depth + 1, out);
  for (const char* key : {"if", "then", "else"})
    if (auto it = schema.find(key); it != schema.end()) collect_asset_refs(doc, *it, at, depth + 1, out);
}

TEST(JsonSchema, AssetReferencesAreWhereTheContractSays) {
  std::set<std::string> found;
  collect_asset_refs("job.schema.json", *contract_schemas().document("job.schema.json"), "", 0, &found);
  const std::set<std::string> listed(std::begin(kAssetRefPointers), std::end(kAssetRefPointers));
  EXPECT_EQ(found, listed);
}

TEST(JsonSchema, ValidateAllReportsEveryErrorInDocumentOrder) {
  json doc = cornell_job();
  doc["render"]["spp"] = 0;
  doc["render"]["width"] = 1.5;
  doc["scene"]["materials"]["light"]["albdo"] = 0.5;
  doc["scene"]["objects"][0]["material"] = 7;
  const auto errors = contract_schemas().validate_all(doc, "job.schema.json");
  std::vector<std::string> pointers;
  for (const SchemaError& e : errors) pointers.push_back(e.pointer);
  EXPECT_EQ(pointers, (std::vector<std::string>{"/render/spp", "/render/width", "/scene/materials/light/albdo",
                                                "/scene/objects/0/material"}));
  // The first of them is the one error validate() reports.
  auto first = validate_job(doc);
  ASSERT_TRUE(first);
  EXPECT_EQ(first->pointer, "/render/spp");
  EXPECT_TRUE(contract_schemas().validate_all(cornell_job(), "job.schema.json").empty());
  // At most max_errors of them.
  EXPECT_EQ(contract_schemas().validate_all(doc, "job.schema.json", 64, 2).size(), 2u);
}

TEST(JsonSchema, ValidateAllKeepsOnlyTheBranchThatGotFurthest) {
  // A colour is a number or an array of three: the failed number branch adds nothing to the array's two errors.
  json doc = cornell_job();
  doc["scene"]["materials"]["light"]["radiance"] = json::array({-1, 1, -1});
  const auto errors = contract_schemas().validate_all(doc, "job.schema.json");
  ASSERT_EQ(errors.size(), 2u);
  EXPECT_EQ(errors[0].pointer, "/scene/materials/light/radiance/0");
  EXPECT_EQ(errors[1].pointer, "/scene/materials/light/radiance/2");
}

TEST(JsonSchema, IntegerLimitsPrintAsIntegers) {
  json doc = cornell_job();
  doc["render"]["spp"] = 0;
  auto e = validate_job(doc);
  ASSERT_TRUE(e);
  EXPECT_EQ(e->message, "must be at least 1");
  SchemaSet set;
  set.add("n.json", json::parse(R"({"minimum": 0.5, "exclusiveMaximum": 2.0})"));
  EXPECT_EQ(set.validate(json(0.25), "n.json")->message, "must be at least 0.5");
  EXPECT_EQ(set.validate(json(3), "n.json")->message, "must be less than 2");
}

TEST(JsonSchema, UnknownNamesSuggestTheClosestKnownOne) {
  json doc = cornell_job();
  doc["scene"]["materials"]["white"]["albdo"] = 0.5;
  auto e = validate_job(doc);
  ASSERT_TRUE(e);
  EXPECT_EQ(e->message, "unknown property \"albdo\" (did you mean \"albedo\"?)");
  doc = cornell_job();
  doc["render"]["estimator"] = "mist";
  e = validate_job(doc);
  ASSERT_TRUE(e);
  EXPECT_NE(e->message.find("(did you mean \"mis\"?)"), std::string::npos) << e->message;
}

TEST(DidYouMean, SuggestsOnlyCloseNames) {
  EXPECT_EQ(edit_distance("albdo", "albedo"), 1u);
  EXPECT_EQ(edit_distance("mirorr", "mirror"), 1u);  // a transposition is one edit
  EXPECT_EQ(edit_distance("Lambert", "lambert"), 0u);
  EXPECT_EQ(edit_distance("", "abc"), 3u);
  const std::vector<std::string> names = {"albedo", "alpha", "emission"};
  EXPECT_EQ(did_you_mean("albdo", names), " (did you mean \"albedo\"?)");
  EXPECT_EQ(did_you_mean("emision", names), " (did you mean \"emission\"?)");
  EXPECT_EQ(did_you_mean("x", names), "");
  EXPECT_EQ(did_you_mean("roughness", names), "");
  EXPECT_EQ(did_you_mean("albedo", names), "");  // a known name is not unknown
  EXPECT_EQ(did_you_mean("--widht", {"--width", "--height"}), " (did you mean \"--width\"?)");
  EXPECT_EQ(did_you_mean(std::string(100, 'a'), names), "");
}

}  // namespace
}  // namespace tessera::proto
