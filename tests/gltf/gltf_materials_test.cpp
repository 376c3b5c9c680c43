// glTF material extensions mapped onto tessera's models: KHR_materials_pbrSpecularGlossiness converted to
// metallic-roughness as the extension's conversion example does, textures included.
#include <gtest/gtest.h>

#include <unistd.h>

#include "renderer/gltf/internal.h"
#include "renderer/job.h"
#include "tests/renderer/gltf_fixture.h"

namespace tessera {
namespace {

using nlohmann::json;

json spec_gloss(const json& ext) {
  return {{"name", "sg"}, {"extensions", {{"KHR_materials_pbrSpecularGlossiness", ext}}}};
}

TEST(GltfMaterials, SpecularGlossinessFactorsBecomeMetallicRoughness) {
  json doc = json::object();
  std::map<std::string, std::shared_ptr<const ImagePixels>> images;
  std::vector<std::string> warnings;
  // A metal: no diffuse, a gold specular colour. Metallic 1, base colour the specular colour, roughness 1 - 0.8.
  json gold = gltf::spec_gloss_to_metal_rough(
      doc,
      spec_gloss({{"diffuseFactor", {0, 0, 0, 1}}, {"specularFactor", {1.0, 0.766, 0.336}}, {"glossinessFactor", 0.8}}),
      images, &warnings);
  const json& g = gold["pbrMetallicRoughness"];
  EXPECT_NEAR(g["metallicFactor"].get<double>(), 1.0, 1e-9);
  EXPECT_NEAR(g["roughnessFactor"].get<double>(), 0.2, 1e-9);
  EXPECT_NEAR(g["baseColorFactor"][0].get<double>(), 1.0, 1e-6);
  EXPECT_NEAR(g["baseColorFactor"][1].get<double>(), 0.766, 1e-6);
  EXPECT_NEAR(g["baseColorFactor"][2].get<double>(), 0.336, 1e-6);
  EXPECT_FALSE(gold["extensions"].contains("KHR_materials_pbrSpecularGlossiness"));
  // A plastic: the dielectric 4 % specular. Metallic 0, base colour the diffuse colour, its alpha kept.
  json plastic = gltf::spec_gloss_to_metal_rough(
      doc,
      spec_gloss(
          {{"diffuseFactor", {0.5, 0.2, 0.1, 0.7}}, {"specularFactor", {0.04, 0.04, 0.04}}, {"glossinessFactor", 0.4}}),
      images, &warnings);
  const json& p = plastic["pbrMetallicRoughness"];
  EXPECT_NEAR(p["metallicFactor"].get<double>(), 0.0, 1e-9);
  EXPECT_NEAR(p["roughnessFactor"].get<double>(), 0.6, 1e-9);
  EXPECT_NEAR(p["baseColorFactor"][0].get<double>(), 0.5, 1e-9);
  EXPECT_NEAR(p["baseColorFactor"][1].get<double>(), 0.2, 1e-9);
  EXPECT_NEAR(p["baseColorFactor"][3].get<double>(), 0.7, 1e-9);
  ASSERT_EQ(warnings.size(), 2u);
  EXPECT_NE(warnings[0].find("approximated"), std::string::npos) << warnings[0];
}

TEST(GltfMaterials, SpecularGlossinessTextureIsBakedPerTexel) {
  // Texel 0: white specular, fully glossy (a smooth metal); texel 1: the dielectric 4 % (sRGB 56), glossiness 0.
  auto sg = std::make_shared<ImagePixels>();
  sg->width = 2;
  sg->height = 1;
  sg->channels = 4;
  sg->data.assign({255, 255, 255, 255, 56, 56, 56, 0});
  std::map<std::string, std::shared_ptr<const ImagePixels>> images = {{"image0", sg}};
  json doc = {{"images", {json::object()}}, {"textures", {{{"source", 0}, {"sampler", 0}}}}};
  json m = gltf::spec_gloss_to_metal_rough(
      doc, spec_gloss({{"diffuseFactor", {0.5, 0.5, 0.5, 1}}, {"specularGlossinessTexture", {{"index", 0}}}}), images,
      nullptr);
  const json& pbr = m["pbrMetallicRoughness"];
  ASSERT_TRUE(pbr.contains("metallicRoughnessTexture"));
  const int tex = pbr["metallicRoughnessTexture"]["index"].get<int>();
  ASSERT_EQ(tex, 1);
  EXPECT_EQ(doc["textures"][tex]["sampler"], 0);
  const int source = doc["textures"][tex]["source"].get<int>();
  ASSERT_TRUE(images.count("image" + std::to_string(source)));
  const ImagePixels& baked = *images["image" + std::to_string(source)];
  ASSERT_EQ(baked.width, 2);
  EXPECT_EQ(baked.data[1], 0);    // roughness of texel 0 (G)
  EXPECT_EQ(baked.data[2], 255);  // metallic of texel 0 (B)
  EXPECT_EQ(baked.data[5], 255);  // roughness of texel 1
  EXPECT_EQ(baked.data[6], 0);    // metallic of texel 1
  EXPECT_EQ(pbr["metallicFactor"], 1.0);
  EXPECT_EQ(pbr["roughnessFactor"], 1.0);
}

// The Khronos sample SpecGlossVsMetalRough: its gold is in the specular-glossiness texture, over a black diffuse
// texture. Converted per texel from both textures, the gold texel is a gold metal (metallic 1, base colour the
// specular colour) and the black-specular texel a dielectric with the diffuse colour; the diffuse alpha is kept.
TEST(GltfMaterials, AMetalInTheSpecularTextureOverABlackDiffuseTextureIsAMetalOfThatColour) {
  auto sg = std::make_shared<ImagePixels>();  // texel 0: gold (sRGB 255, 225, 156), glossy; texel 1: 4 % grey
  sg->width = 2;
  sg->height = 1;
  sg->channels = 4;
  sg->data.assign({255, 225, 156, 255, 56, 56, 56, 128});
  auto diffuse = std::make_shared<ImagePixels>();  // black, then mid grey; alpha 1 and 0.2
  diffuse->width = 2;
  diffuse->height = 1;
  diffuse->channels = 4;
  diffuse->data.assign({0, 0, 0, 255, 188, 188, 188, 51});
  std::map<std::string, std::shared_ptr<const ImagePixels>> images = {{"image0", sg}, {"image1", diffuse}};
  json doc = {{"images", {json::object(), json::object()}}, {"textures", {{{"source", 0}}, {{"source", 1}}}}};
  json m = gltf::spec_gloss_to_metal_rough(
      doc, spec_gloss({{"specularGlossinessTexture", {{"index", 0}}}, {"diffuseTexture", {{"index", 1}}}}), images,
      nullptr);
  const json& pbr = m["pbrMetallicRoughness"];
  ASSERT_TRUE(pbr.contains("baseColorTexture"));
  ASSERT_TRUE(pbr.contains("metallicRoughnessTexture"));
  auto pixels = [&](const char* key) {
    const int tex = pbr[key]["index"].get<int>();
    return images.at("image" + std::to_string(doc["textures"][tex]["source"].get<int>()));
  };
  const ImagePixels& base = *pixels("baseColorTexture");
  const ImagePixels& mr = *pixels("metallicRoughnessTexture");
  EXPECT_EQ(mr.data[2], 255);  // metallic of the gold texel
  EXPECT_EQ(mr.data[1], 0);    // its roughness
  EXPECT_NEAR(base.data[0], 255, 1);
  EXPECT_NEAR(base.data[1], 225, 1);
  EXPECT_NEAR(base.data[2], 156, 1);
  EXPECT_EQ(base.data[3], 255);
  EXPECT_EQ(mr.data[6], 0);  // the grey texel: a dielectric of the diffuse colour
  EXPECT_NEAR(mr.data[5], 128, 1);
  EXPECT_NEAR(base.data[4], 188, 1);
  EXPECT_EQ(base.data[7], 51);
  EXPECT_EQ(pbr["baseColorFactor"], json({1.0, 1.0, 1.0, 1.0}));
  // A diffuse texture mapped otherwise (another texCoord) is not read per texel: it stays the base colour's.
  json other = gltf::spec_gloss_to_metal_rough(
      doc,
      spec_gloss({{"specularGlossinessTexture", {{"index", 0}}}, {"diffuseTexture", {{"index", 1}, {"texCoord", 1}}}}),
      images, nullptr);
  EXPECT_EQ(other["pbrMetallicRoughness"]["baseColorTexture"]["index"], 1);
}

TEST(GltfMaterials, SpecularGlossinessAssetsImportWithAWarningSayingItIsApproximated) {
  test::GltfBuilder b;
  const int mat =
      b.material(spec_gloss({{"diffuseFactor", {0.5, 0.2, 0.1, 1}}, {"specularFactor", {0.04, 0.04, 0.04}}}));
  b.node({{"mesh", b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, mat)}}, true);
  b.doc["extensionsUsed"] = {"KHR_materials_pbrSpecularGlossiness"};
  b.doc["extensionsRequired"] = {"KHR_materials_pbrSpecularGlossiness"};
  const auto dir = std::filesystem::temp_directory_path() / ("tessera-gltf-materials-" + std::to_string(::getpid()));
  const auto path = b.write(dir, "specgloss");
  Scene scene;
  const GltfImport imported = import_gltf(path, "/scene/gltf", scene, {});
  std::filesystem::remove_all(dir);
  ASSERT_EQ(imported.warnings.size(), 1u);
  EXPECT_NE(imported.warnings[0].find("KHR_materials_pbrSpecularGlossiness is approximated"), std::string::npos)
      << imported.warnings[0];
}

// KHR_materials_anisotropy (the extension's specification): strength, rotation and the texture, whose B scales the
// strength and whose RG is the direction in tangent space.
TEST(GltfMaterials, AnisotropyParametersAreRead) {
  const json doc = {{"images", {json::object()}}, {"textures", {{{"source", 0}}}}};
  const json m = {
      {"extensions",
       {{"KHR_materials_anisotropy",
         {{"anisotropyStrength", 0.6}, {"anisotropyRotation", 0.5}, {"anisotropyTexture", {{"index", 0}}}}}}}};
  std::vector<std::string> warnings;
  const json p = gltf::material_params(doc, m, &warnings);
  EXPECT_TRUE(warnings.empty());
  ASSERT_TRUE(p.contains("anisotropy")) << p.dump();
  EXPECT_EQ(p["anisotropy"]["texture"], "#image0");
  EXPECT_EQ(p["anisotropy"]["channel"], 2);
  EXPECT_EQ(p["anisotropy"]["factor"], 0.6);
  EXPECT_EQ(p["anisotropy"]["colorspace"], "linear");
  EXPECT_EQ(p["anisotropy_rotation"], 0.5);
  ASSERT_TRUE(p.contains("anisotropy_direction")) << p.dump();
  EXPECT_EQ(p["anisotropy_direction"]["texture"], "#image0");
  EXPECT_EQ(p["anisotropy_direction"]["colorspace"], "linear");
  EXPECT_FALSE(p["anisotropy_direction"].contains("channel"));
}

TEST(GltfMaterials, AnAnisotropicAssetImportsWithoutAWarningAndAsksForTangents) {
  test::GltfBuilder b;
  const int mat = b.material(
      {{"name", "brushed"},
       {"pbrMetallicRoughness", {{"metallicFactor", 1.0}, {"roughnessFactor", 0.3}}},
       {"extensions", {{"KHR_materials_anisotropy", {{"anisotropyStrength", 0.8}, {"anisotropyRotation", 1.0}}}}}});
  b.node({{"mesh", b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, mat)}}, true);
  b.doc["extensionsUsed"] = {"KHR_materials_anisotropy"};
  b.doc["extensionsRequired"] = {"KHR_materials_anisotropy"};
  const auto dir = std::filesystem::temp_directory_path() / ("tessera-gltf-aniso-" + std::to_string(::getpid()));
  const auto path = b.write(dir, "anisotropy");
  Scene scene;
  const GltfImport imported = import_gltf(path, "/scene/gltf", scene, {});
  std::filesystem::remove_all(dir);
  EXPECT_TRUE(imported.warnings.empty()) << imported.warnings.front();
  ASSERT_EQ(scene.materials.size(), 1u);
  EXPECT_FALSE(scene.materials[0]->isotropic());  // the hit's tangent orients the lobe
}

// KHR_materials_iridescence (the extension's specification): the factor (times the texture's R), the film's index,
// and its thickness between the minimum and the maximum by the thickness texture's G (the maximum without one).
TEST(GltfMaterials, IridescenceParametersAreRead) {
  const json doc = {{"images", {json::object(), json::object()}}, {"textures", {{{"source", 0}}, {{"source", 1}}}}};
  const json m = {{"extensions",
                   {{"KHR_materials_iridescence",
                     {{"iridescenceFactor", 0.9},
                      {"iridescenceTexture", {{"index", 0}}},
                      {"iridescenceIor", 1.8},
                      {"iridescenceThicknessMinimum", 250},
                      {"iridescenceThicknessMaximum", 650},
                      {"iridescenceThicknessTexture", {{"index", 1}}}}}}}};
  std::vector<std::string> warnings;
  const json p = gltf::material_params(doc, m, &warnings);
  EXPECT_TRUE(warnings.empty());
  ASSERT_TRUE(p.contains("iridescence")) << p.dump();
  EXPECT_EQ(p["iridescence"]["texture"], "#image0");
  EXPECT_EQ(p["iridescence"]["channel"], 0);
  EXPECT_EQ(p["iridescence"]["factor"], 0.9);
  EXPECT_EQ(p["iridescence"]["colorspace"], "linear");
  EXPECT_EQ(p["iridescence_ior"], 1.8);
  EXPECT_EQ(p["iridescence_thickness_minimum"], 250);
  EXPECT_EQ(p["iridescence_thickness_maximum"], 650);
  ASSERT_TRUE(p.contains("iridescence_thickness")) << p.dump();
  EXPECT_EQ(p["iridescence_thickness"]["texture"], "#image1");
  EXPECT_EQ(p["iridescence_thickness"]["channel"], 1);
  EXPECT_EQ(p["iridescence_thickness"]["colorspace"], "linear");
  // The spec's defaults: index 1.3, 100..400 nm, the maximum without a texture.
  const json q = gltf::material_params(doc, {{"extensions", {{"KHR_materials_iridescence", json::object()}}}}, nullptr);
  EXPECT_EQ(q["iridescence"], 0.0);
  EXPECT_EQ(q["iridescence_ior"], 1.3);
  EXPECT_EQ(q["iridescence_thickness_minimum"], 100.0);
  EXPECT_EQ(q["iridescence_thickness_maximum"], 400.0);
  EXPECT_EQ(q["iridescence_thickness"], 1.0);
}

TEST(GltfMaterials, AnIridescentAssetImportsWithoutAWarning) {
  test::GltfBuilder b;
  const int mat = b.material(
      {{"name", "beetle"},
       {"pbrMetallicRoughness", {{"metallicFactor", 1.0}, {"roughnessFactor", 0.3}}},
       {"extensions",
        {{"KHR_materials_iridescence", {{"iridescenceFactor", 1.0}, {"iridescenceThicknessMaximum", 500}}}}}});
  b.node({{"mesh", b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, mat)}}, true);
  b.doc["extensionsUsed"] = {"KHR_materials_iridescence"};
  b.doc["extensionsRequired"] = {"KHR_materials_iridescence"};
  const auto dir = std::filesystem::temp_directory_path() / ("tessera-gltf-irid-" + std::to_string(::getpid()));
  const auto path = b.write(dir, "iridescence");
  Scene scene;
  const GltfImport imported = import_gltf(path, "/scene/gltf", scene, {});
  std::filesystem::remove_all(dir);
  EXPECT_TRUE(imported.warnings.empty()) << imported.warnings.front();
  ASSERT_EQ(scene.materials.size(), 1u);
}

// KHR_materials_dispersion (the extension's specification): dispersion, 20 / V_d, read onto the material, which then
// disperses when KHR_materials_volume makes it a solid; on a thin wall it has no effect, and a warning says so.
TEST(GltfMaterials, DispersionIsReadAndDispersesASolid) {
  const json doc = json::object();
  const json solid = {{"name", "gem"},
                      {"extensions",
                       {{"KHR_materials_transmission", {{"transmissionFactor", 1.0}}},
                        {"KHR_materials_volume", {{"thicknessFactor", 1.0}}},
                        {"KHR_materials_dispersion", {{"dispersion", 0.36}}}}}};
  std::vector<std::string> warnings;
  const json p = gltf::material_params(doc, solid, &warnings);
  EXPECT_TRUE(warnings.empty());
  EXPECT_EQ(p["dispersion"], 0.36);
  MaterialContext ctx;
  EXPECT_TRUE(MaterialRegistry::builtin().create(p, "/m", ctx)->dispersive());
  // Without a volume the surface is thin-walled: read, not dispersive, and warned about, naming the material.
  json thin = solid;
  thin["extensions"].erase("KHR_materials_volume");
  warnings.clear();
  const json q = gltf::material_params(doc, thin, &warnings);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("\"gem\""), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[0].find("KHR_materials_dispersion"), std::string::npos) << warnings[0];
  EXPECT_FALSE(MaterialRegistry::builtin().create(q, "/m", ctx)->dispersive());
  // The default, 0, is no dispersion.
  const json none =
      gltf::material_params(doc, {{"extensions", {{"KHR_materials_dispersion", json::object()}}}}, nullptr);
  EXPECT_EQ(none["dispersion"], 0.0);
}

TEST(GltfMaterials, ADispersiveAssetImportsWithoutAWarning) {
  test::GltfBuilder b;
  const int mat = b.material({{"name", "prism"},
                              {"extensions",
                               {{"KHR_materials_transmission", {{"transmissionFactor", 1.0}}},
                                {"KHR_materials_volume", {{"thicknessFactor", 0.5}}},
                                {"KHR_materials_dispersion", {{"dispersion", 1.0}}}}}});
  b.node({{"mesh", b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, mat)}}, true);
  b.doc["extensionsUsed"] = {"KHR_materials_transmission", "KHR_materials_volume", "KHR_materials_dispersion"};
  b.doc["extensionsRequired"] = {"KHR_materials_dispersion"};
  const auto dir = std::filesystem::temp_directory_path() / ("tessera-gltf-disp-" + std::to_string(::getpid()));
  const auto path = b.write(dir, "dispersion");
  Scene scene;
  const GltfImport imported = import_gltf(path, "/scene/gltf", scene, {});
  std::filesystem::remove_all(dir);
  EXPECT_TRUE(imported.warnings.empty()) << imported.warnings.front();
  ASSERT_EQ(scene.materials.size(), 1u);
  EXPECT_TRUE(scene.materials[0]->dispersive());
}

// KHR_materials_diffuse_transmission (the extension's specification): the factor (times the texture's A, linear)
// and the colour (times its sRGB texture).
TEST(GltfMaterials, DiffuseTransmissionParametersAreRead) {
  const json doc = {{"images", {json::object(), json::object()}}, {"textures", {{{"source", 0}}, {{"source", 1}}}}};
  const json m = {{"extensions",
                   {{"KHR_materials_diffuse_transmission",
                     {{"diffuseTransmissionFactor", 0.7},
                      {"diffuseTransmissionTexture", {{"index", 0}}},
                      {"diffuseTransmissionColorFactor", {0.9, 0.5, 0.1}},
                      {"diffuseTransmissionColorTexture", {{"index", 1}}}}}}}};
  std::vector<std::string> warnings;
  const json p = gltf::material_params(doc, m, &warnings);
  EXPECT_TRUE(warnings.empty());
  ASSERT_TRUE(p.contains("diffuse_transmission")) << p.dump();
  EXPECT_EQ(p["diffuse_transmission"]["texture"], "#image0");
  EXPECT_EQ(p["diffuse_transmission"]["channel"], 3);
  EXPECT_EQ(p["diffuse_transmission"]["factor"], 0.7);
  EXPECT_EQ(p["diffuse_transmission"]["colorspace"], "linear");
  ASSERT_TRUE(p.contains("diffuse_transmission_color")) << p.dump();
  EXPECT_EQ(p["diffuse_transmission_color"]["texture"], "#image1");
  EXPECT_EQ(p["diffuse_transmission_color"]["factor"], json({0.9, 0.5, 0.1}));
  EXPECT_EQ(p["diffuse_transmission_color"]["colorspace"], "srgb");
  // Factors alone, on a refracting volume: read, and a warning that it is not drawn there.
  const json solid = {{"name", "leaf"},
                      {"extensions",
                       {{"KHR_materials_diffuse_transmission", {{"diffuseTransmissionFactor", 0.4}}},
                        {"KHR_materials_volume", {{"thicknessFactor", 1.0}}}}}};
  const json q = gltf::material_params(doc, solid, &warnings);
  EXPECT_EQ(q["diffuse_transmission"], 0.4);
  EXPECT_EQ(q["diffuse_transmission_color"], json({1, 1, 1}));
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("\"leaf\": KHR_materials_diffuse_transmission is not drawn"), std::string::npos)
      << warnings[0];
}

TEST(GltfMaterials, ADiffuselyTransmittingAssetImportsWithoutAWarning) {
  test::GltfBuilder b;
  const int mat =
      b.material({{"name", "paper"},
                  {"pbrMetallicRoughness", {{"metallicFactor", 0.0}}},
                  {"extensions", {{"KHR_materials_diffuse_transmission", {{"diffuseTransmissionFactor", 1.0}}}}}});
  b.node({{"mesh", b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, mat)}}, true);
  b.doc["extensionsUsed"] = {"KHR_materials_diffuse_transmission"};
  b.doc["extensionsRequired"] = {"KHR_materials_diffuse_transmission"};
  const auto dir = std::filesystem::temp_directory_path() / ("tessera-gltf-difftrans-" + std::to_string(::getpid()));
  const auto path = b.write(dir, "difftrans");
  Scene scene;
  const GltfImport imported = import_gltf(path, "/scene/gltf", scene, {});
  std::filesystem::remove_all(dir);
  EXPECT_TRUE(imported.warnings.empty()) << imported.warnings.front();
  ASSERT_EQ(scene.materials.size(), 1u);
}

// One triangle with material "plain" (0), and variants "midnight_blue" (material "blue", 1) and "crimson" (material
// "red", 2) mapped on its primitive; material "unused" (3) is no variant's.
std::filesystem::path write_variants(const std::filesystem::path& dir) {
  test::GltfBuilder b;
  for (const char* name : {"plain", "blue", "red", "unused"}) b.material({{"name", name}});
  b.node({{"mesh", b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, 0)}}, true);
  b.doc["meshes"][0]["primitives"][0]["extensions"] = {
      {"KHR_materials_variants",
       {{"mappings", {{{"material", 1}, {"variants", {0}}}, {{"material", 2}, {"variants", {1}}}}}}}};
  b.doc["extensions"] = {
      {"KHR_materials_variants", {{"variants", {{{"name", "midnight_blue"}}, {{"name", "crimson"}}}}}}};
  b.doc["extensionsUsed"] = {"KHR_materials_variants"};
  return b.write(dir, "variants");
}

std::string material_of_first_mesh(const Scene& scene) {
  return scene.material_names.at(scene.meshes.at(0).material);
}

TEST(GltfMaterials, AVariantChosenByNameGivesItsMaterials) {
  const auto dir = std::filesystem::temp_directory_path() / ("tessera-gltf-variants-" + std::to_string(::getpid()));
  const auto path = write_variants(dir);
  for (const auto& [variant, material] :
       std::vector<std::pair<std::string, std::string>>{{"", "plain"}, {"midnight_blue", "blue"}, {"crimson", "red"}}) {
    Scene scene;
    GltfImportOptions options;
    options.variant = variant;
    const GltfImport imported = import_gltf(path, "/scene/gltf", scene, options);
    EXPECT_EQ(material_of_first_mesh(scene), material) << "variant \"" << variant << "\"";
    EXPECT_TRUE(imported.warnings.empty()) << imported.warnings.front();
  }
  // Through a job document: the field is scene.gltf_variant; an unknown name is refused there, naming the closest.
  JobLoadOptions opts;
  opts.scene.asset_root = dir;
  json job = {{"kind", "scene"},
              {"scene", {{"gltf", "variants.gltf"}, {"gltf_variant", "crimson"}}},
              {"render", {{"width", 8}, {"height", 8}, {"spp", 1}}}};
  EXPECT_EQ(material_of_first_mesh(*load_job(job, opts).scene), "red");
  job["scene"]["gltf_variant"] = "midnight_blu";
  try {
    load_job(job, opts);
    ADD_FAILURE() << "an unknown variant was accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.pointer(), "/scene/gltf_variant");
    EXPECT_NE(std::string(e.what()).find("(did you mean \"midnight_blue\"?)"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("\"crimson\""), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tessera
