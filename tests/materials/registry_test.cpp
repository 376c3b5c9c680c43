// The registry and proto/schemas/material.schema.json agree: every type in the schema's enum is registered and vice
// versa, every model has its allOf entry and $defs object, every schema default is accepted by the factory, and an
// out-of-range parameter raises SceneError pointing at that parameter.
#include <fstream>
#include <set>

#include <gtest/gtest.h>

#include "renderer/material/material.h"
#include "renderer/medium.h"
#include "renderer/scene_error.h"
#include "renderer/texture.h"

namespace tessera {
namespace {

using nlohmann::json;

json load_schema() {
  std::ifstream in("proto/schemas/material.schema.json");  // tests run in the source root
  EXPECT_TRUE(in.good()) << "proto/schemas/material.schema.json not found from the working directory";
  return json::parse(in);
}

std::set<std::string> schema_types(const json& schema) {
  std::set<std::string> out;
  for (const json& t : schema["properties"]["type"]["enum"]) out.insert(t.get<std::string>());
  return out;
}

TEST(MaterialRegistry, SchemaEnumAndRegistryAgree) {
  json schema = load_schema();
  std::set<std::string> in_schema = schema_types(schema);
  std::vector<std::string> registered = MaterialRegistry::builtin().types();
  std::set<std::string> in_registry(registered.begin(), registered.end());
  for (const std::string& t : in_schema) EXPECT_TRUE(in_registry.count(t)) << t << " is in the schema only";
  for (const std::string& t : in_registry)
    EXPECT_TRUE(in_schema.count(t)) << t << " is registered but not in the schema";
  // One allOf if/then per type naming its $defs entry, which is an object schema with title and description.
  std::set<std::string> in_all_of;
  for (const json& entry : schema["allOf"]) {
    std::string t = entry["if"]["properties"]["type"]["const"];
    in_all_of.insert(t);
    EXPECT_EQ(entry["then"]["$ref"], "#/$defs/" + t);
  }
  EXPECT_EQ(in_all_of, in_schema);
  for (const std::string& t : in_schema) {
    const json& def = schema["$defs"][t];
    EXPECT_EQ(def["type"], "object") << t;
    EXPECT_TRUE(def.contains("title") && def.contains("description")) << t;
    EXPECT_EQ(def["additionalProperties"], false) << t;
    for (const auto& [key, prop] : def["properties"].items()) {
      if (key == "type") continue;
      EXPECT_TRUE(prop.contains("description")) << t << "." << key;
    }
  }
}

// The material made of every default the schema declares for the model.
json defaults_of(const json& def, const std::string& type) {
  json m = {{"type", type}};
  for (const auto& [key, prop] : def["properties"].items()) {
    if (key != "type" && prop.contains("default")) m[key] = prop["default"];
  }
  return m;
}

TEST(MaterialRegistry, EverySchemaDefaultIsAccepted) {
  json schema = load_schema();
  MaterialContext ctx;
  for (const std::string& t : schema_types(schema)) {
    json m = defaults_of(schema["$defs"][t], t);
    EXPECT_NO_THROW(MaterialRegistry::builtin().create(m, "/m", ctx)) << m.dump();
  }
}

TEST(MaterialRegistry, OutOfRangeParametersNameTheField) {
  json schema = load_schema();
  MaterialContext ctx;
  int checked = 0;
  for (const std::string& t : schema_types(schema)) {
    const json& def = schema["$defs"][t];
    for (const auto& [key, prop] : def["properties"].items()) {
      std::vector<double> bad;
      if (prop.contains("maximum")) bad.push_back(prop["maximum"].get<double>() * 2 + 1);
      if (prop.contains("minimum")) bad.push_back(prop["minimum"].get<double>() - 1);
      for (double v : bad) {
        json m = {{"type", t}, {key, v}};
        try {
          MaterialRegistry::builtin().create(m, "/m", ctx);
          ADD_FAILURE() << t << "." << key << " = " << v << " was accepted";
        } catch (const SceneError& e) {
          EXPECT_EQ(e.pointer(), "/m/" + key) << t << "." << key << ": " << e.what();
          ++checked;
        }
      }
    }
    // Wrong kinds of values and unknown enum strings are refused too.
    for (const auto& [key, prop] : def["properties"].items()) {
      if (!prop.contains("enum")) continue;
      json m = {{"type", t}, {key, "no-such-value"}};
      EXPECT_THROW(MaterialRegistry::builtin().create(m, "/m", ctx), SceneError) << t << "." << key;
    }
  }
  EXPECT_GT(checked, 40);
  // Nested materials report their own pointers; energy constraints name the field.
  try {
    MaterialRegistry::builtin().create({{"type", "mix"}, {"b", {{"type", "conductor"}, {"roughness", 7}}}}, "/m", ctx);
    ADD_FAILURE();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), "/m/b/roughness");
  }
  EXPECT_THROW(MaterialRegistry::builtin().create({{"type", "phong"}, {"kd", 0.7}, {"ks", 0.6}}, "/m", ctx),
               SceneError);
  try {
    MaterialRegistry::builtin().create({{"type", "conductor"}, {"metal", "unobtainium"}}, "/m", ctx);
    ADD_FAILURE();
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), "/m/metal");
  }
}

TEST(MaterialRegistry, EveryModelBuildsABsdfAtItsDefaults) {
  json schema = load_schema();
  MaterialContext ctx;
  for (const std::string& t : schema_types(schema)) {
    auto m = MaterialRegistry::builtin().create({{"type", t}}, "/m", ctx);
    ScratchArena arena;
    ShadingPoint sp;
    const Bsdf* bsdf = m->bsdf(sp, arena);
    if (t == "emission") {
      EXPECT_EQ(bsdf, nullptr);
      EXPECT_TRUE(m->emissive());
      continue;
    }
    ASSERT_NE(bsdf, nullptr) << t;
    EXPECT_NE(bsdf->flags(), 0u) << t;
  }
}

// A material's common parameters: the model's own, the JSON's common keys over them, and what the caller read
// elsewhere over those; one interior only, whichever of the three defines it.
TEST(MaterialRegistry, CommonParametersComeFromTheModelTheKeysAndTheCaller) {
  const MaterialRegistry& registry = MaterialRegistry::builtin();
  MaterialContext ctx;
  const double white[3] = {1, 1, 1};
  Material::Common given;
  given.alpha_mode = Material::AlphaMode::kMask;
  given.alpha_cutoff = 0.25f;
  given.normal_map = make_checker_texture(Rgb(0.5f, 0.5f, 1), Rgb(0.5f, 0.5f, 1), 1);
  given.normal_scale = 2;
  given.interior = absorbing_medium(white, 1);
  const Medium* medium = given.interior.get();
  auto m = registry.create({{"type", "dielectric"}, {"emission", 2}}, "/m", ctx, given);
  EXPECT_TRUE(m->emissive());
  EXPECT_EQ(m->alpha_mode(), Material::AlphaMode::kMask);
  EXPECT_EQ(m->alpha_cutoff(), 0.25f);
  EXPECT_EQ(m->normal_scale(), 2.0f);
  EXPECT_EQ(m->interior(), medium);
  // A texture the caller gave is read as the JSON's are: the hits' footprints are worked out for it.
  EXPECT_TRUE(m->reads_textures());
  EXPECT_FALSE(registry.create({{"type", "dielectric"}}, "/m", ctx)->reads_textures());
  // The model's own: the emission model's radiance, a subsurface interior.
  EXPECT_TRUE(registry.create({{"type", "emission"}}, "/m", ctx)->emissive());
  EXPECT_NE(registry.create({{"type", "subsurface"}}, "/m", ctx)->interior(), nullptr);
  // A second interior is refused, naming the material (or the attenuation key that gives it).
  Material::Common enclosing;
  enclosing.interior = absorbing_medium(white, 1);
  for (const json& doc : {json{{"type", "subsurface"}}, json{{"type", "dielectric"}, {"attenuation_distance", 2}}}) {
    try {
      registry.create(doc, "/m", ctx, enclosing);
      ADD_FAILURE() << doc.dump() << " took a second interior";
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), "/m") << doc.dump();
    }
  }
  EXPECT_THROW(registry.create({{"type", "subsurface"}, {"attenuation_distance", 2}}, "/m", ctx), SceneError);
}

}  // namespace
}  // namespace tessera
