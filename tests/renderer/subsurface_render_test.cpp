// Statistical tests of subsurface materials (subsurface.h) with the path tracer: the white furnace (a subsurface
// sphere of multiple-scattering albedo 1 vanishes under a uniform sky, behind an index-matched, a smooth and a rough
// dielectric boundary), energy (a lower subsurface_color gives a darker object, in order), the meaning of
// subsurface_color (a thick index-matched slab reflects it under uniform light), and the subsurface materials' input
// refused where it is wrong, bdpt and light included; guided walks agree with plain ones.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>

#include "renderer/job.h"
#include "renderer/scene_error.h"
#include "renderer/session.h"
#include "tests/renderer/test_util.h"

namespace tessera {
namespace {

using nlohmann::json;

using test::render_document;

// Random walks in a dense medium take many steps and, behind glass, many internal reflections: the limits are raised
// so that no path is cut short (cutting one loses its light).
RenderSettings settings(int size, uint32_t spp, uint64_t seed) {
  RenderSettings s;
  s.width = s.height = size;
  s.spp = spp;
  s.seed = seed;
  s.integrator.estimator = Estimator::kMis;
  s.integrator.max_depth = 4096;
  s.integrator.max_volume_depth = 100000;
  s.tile_size = 16;
  return s;
}

// The mean of one channel over the image's pixels and its standard error (pixels are independent estimates).
struct Mean {
  double mean = 0, se = 0;
};
Mean pixel_mean(const std::vector<float>& rgb, int channel) {
  const size_t n = rgb.size() / 3;
  double sum = 0, sum2 = 0;
  for (size_t i = 0; i < n; ++i) {
    const double v = rgb[3 * i + channel];
    sum += v;
    sum2 += v * v;
  }
  const double mean = sum / n, var = (sum2 - n * mean * mean) / (n - 1);
  return {mean, std::sqrt(std::max(var, 0.0) / n)};
}

// A unit sphere of `material`, filling the middle of the view, under a uniform white sky.
json sphere_scene(const json& material) {
  return {
      {"materials", {{"skin", material}}},
      {"objects", json::array({{{"shape", "sphere"}, {"center", {0, 0, 0}}, {"radius", 1}, {"material", "skin"}}})},
      {"camera", {{"from", {0, 0, 3}}, {"to", {0, 0, 0}}, {"fov_deg", 25}}},
      {"environment", {{"color", 1.0}}},
  };
}

json subsurface(double color, double ior, double roughness = 0) {
  return {
      {"type", "subsurface"}, {"subsurface_color", color}, {"subsurface_radius", 0.3}, {"subsurface_radius_scale", 1},
      {"ior", ior},           {"roughness", roughness}};
}

// The white furnace: with subsurface_color 1 the medium does not absorb, and the boundary loses nothing, so every
// path leaves with the sky's radiance 1: the image is 1 within its standard error, channel by channel (the mean free
// paths differ by channel with the default radius scale), for an index-matched and a smooth glass boundary, and for a
// solid gltf_pbr whose base is all subsurface. (A rough boundary is Walter et al.'s single-scattering microfacet
// interface, which loses the light that would scatter between microfacets (Heitz et al. 2016), once per internal
// reflection: it is not a furnace.)
TEST(Subsurface, WhiteFurnaceVanishes) {
  json chromatic = subsurface(1.0, 1.33);
  chromatic.erase("subsurface_radius_scale");
  chromatic["subsurface_radius"] = 0.6;
  chromatic["subsurface_scatter_anisotropy"] = 0.5;
  const json materials[] = {
      subsurface(1.0, 1.0),
      subsurface(1.0, 1.5),
      chromatic,
      {{"type", "gltf_pbr"},
       {"base_color", 1.0},
       {"metallic", 0.0},
       {"roughness", 0.0},
       {"subsurface_weight", 1.0},
       {"subsurface_color", 1.0},
       {"subsurface_radius", 0.3},
       {"subsurface_radius_scale", 1}},
  };
  for (const json& material : materials) {
    const std::vector<float> img = render_document(sphere_scene(material), settings(24, 512, 7));
    for (int c = 0; c < 3; ++c) {
      const Mean m = pixel_mean(img, c);
      std::printf("%s channel %d: %.5f +- %.5f\n", material.dump().c_str(), c, m.mean, m.se);
      // 12 comparisons: |z| < 4 is a 0.1 % false alarm rate for them all; the standard error is small enough that
      // a loss of 2 % is seen.
      EXPECT_LT(std::abs(m.mean - 1) / m.se, 4.0) << material.dump() << ", channel " << c;
      EXPECT_LT(m.se, 0.005) << material.dump();
    }
  }
}

// Energy: the sphere's mean radiance falls, strictly and by more than its noise, as subsurface_color does.
TEST(Subsurface, DarkerColourDarkerObject) {
  double previous = 2, previous_se = 0;
  for (double a : {1.0, 0.8, 0.5, 0.2}) {
    const Mean m = pixel_mean(render_document(sphere_scene(subsurface(a, 1.4)), settings(24, 64, 11)), 1);
    std::printf("subsurface_color %.1f: %.4f +- %.4f\n", a, m.mean, m.se);
    EXPECT_LT(m.mean + 4 * std::hypot(m.se, previous_se), previous) << a;
    previous = m.mean;
    previous_se = m.se;
  }
}

// A closed box mesh from `lo` to `hi`, its triangles wound so that their normals point out.
json box(const Vec3& lo, const Vec3& hi, const std::string& material) {
  json positions = json::array(), indices = json::array();
  for (int i = 0; i < 8; ++i) {
    positions.push_back(i & 1 ? hi.x : lo.x);
    positions.push_back(i & 2 ? hi.y : lo.y);
    positions.push_back(i & 4 ? hi.z : lo.z);
  }
  auto corner = [&](int i) { return Vec3(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z); };
  const Vec3 centre = (lo + hi) * 0.5f;
  // Each face: the four corners with one coordinate bit fixed, in order around the face.
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      const int a = 1 << ((axis + 1) % 3), b = 1 << ((axis + 2) % 3), f = side << axis;
      int q[4] = {f, f | a, f | a | b, f | b};
      const Vec3 n = cross(corner(q[1]) - corner(q[0]), corner(q[2]) - corner(q[0]));
      if (dot(n, corner(q[0]) - centre) < 0) std::swap(q[1], q[3]);
      for (int t : {q[0], q[1], q[2], q[0], q[2], q[3]}) indices.push_back(t);
    }
  }
  return {{"shape", "mesh"}, {"positions", positions}, {"indices", indices}, {"material", material}};
}

// The meaning of subsurface_color: a thick slab behind an index-matched boundary (a box 10^4 mean free paths deep and
// 2 10^4 wide) under a uniform white sky reflects, summed over the hemisphere, subsurface_color: the spherical albedo
// 2 int_0^1 r(mu) mu dmu, with r(mu) the radiance a camera sees at cos mu from the normal (by reciprocity the plane
// albedo at incidence mu), integrated by 3-point Gauss–Legendre quadrature in mu^2 (exact for r of degree 5 in mu^2).
// The inversion inverts van de Hulst's fit of this albedo: the renders agree with A within 0.02 (the fit's accuracy)
// at A = 0.2, 0.5, 0.8 (measured 0.198, 0.497, 0.799), the quadrature's standard error a tenth of that or less.
TEST(Subsurface, ThickSlabReflectsSubsurfaceColor) {
  // Gauss–Legendre nodes and weights on [0, 1] for the variable x = mu^2 (dx = 2 mu dmu).
  const double nodes[3] = {0.5 - std::sqrt(0.15), 0.5, 0.5 + std::sqrt(0.15)};
  const double weights[3] = {5.0 / 18, 8.0 / 18, 5.0 / 18};
  for (double a : {0.2, 0.5, 0.8}) {
    double albedo = 0, var = 0;
    for (int k = 0; k < 3; ++k) {
      const double mu = std::sqrt(nodes[k]), sin_t = std::sqrt(1 - nodes[k]);
      json scene = {
          {"materials",
           {{"slab",
             {{"type", "subsurface"},
              {"ior", 1},
              {"subsurface_color", a},
              {"subsurface_radius", 0.01},
              {"subsurface_radius_scale", 1}}}}},
          {"objects", json::array({box(Vec3(-100, -100, -100), Vec3(100, 0, 100), "slab")})},
          {"camera", {{"from", {sin_t, mu, 0}}, {"to", {0, 0, 0}}, {"fov_deg", 2}}},
          {"environment", {{"color", 1.0}}},
      };
      const Mean m = pixel_mean(render_document(scene, settings(32, 128, 100 + k)), 1);
      std::printf("A %.1f, mu %.3f: r %.4f +- %.4f\n", a, mu, m.mean, m.se);
      albedo += weights[k] * m.mean;
      var += weights[k] * weights[k] * m.se * m.se;
    }
    const double se = std::sqrt(var);
    std::printf("A %.1f: spherical albedo %.4f +- %.4f\n", a, albedo, se);
    // The walk's roulette without a floor (path.cpp) keeps the error small: with the floor of 0.05 per scattering
    // the same renders had a standard error of 0.0044 at A = 0.8.
    EXPECT_LT(se, 0.002) << a;
    EXPECT_NEAR(albedo, a, 0.02) << a;
  }
}

// Guided walks (integrators/guided_walk.h) estimate the same image as plain ones: a chromatic subsurface sphere behind
// glass and one behind an index-matched boundary, rendered with render.subsurface_guiding on and off (other seeds),
// agree channel by channel: the mean of their per-pixel differences is within 4 of its standard errors of zero (the
// sphere's own shading cancels in the difference, so a bias of 1 % is seen).
TEST(Subsurface, GuidedAndPlainWalksAgree) {
  json glass = subsurface(0.8, 1.4, 0.3);
  glass["subsurface_radius_scale"] = {1, 0.5, 0.25};
  const json materials[] = {glass, subsurface(0.5, 1.0)};
  for (const json& material : materials) {
    RenderSettings guided = settings(24, 256, 21), plain = settings(24, 256, 22);
    guided.integrator.subsurface_guiding = true;
    plain.integrator.subsurface_guiding = false;
    const std::vector<float> a = render_document(sphere_scene(material), guided);
    const std::vector<float> b = render_document(sphere_scene(material), plain);
    ASSERT_EQ(a.size(), b.size());
    std::vector<float> difference(a.size());
    for (size_t i = 0; i < a.size(); ++i) difference[i] = a[i] - b[i];
    for (int c = 0; c < 3; ++c) {
      const Mean d = pixel_mean(difference, c), level = pixel_mean(b, c);
      std::printf("%s channel %d: guided - plain %.5f +- %.5f (plain %.4f)\n", material.dump().c_str(), c, d.mean, d.se,
                  level.mean);
      EXPECT_LT(std::abs(d.mean) / d.se, 4.0) << material.dump() << ", channel " << c;
      EXPECT_LT(d.se, 0.01 * level.mean) << material.dump();
    }
  }
}

// Wrong subsurface input is refused naming the field, as a 422 names it; bdpt and light refuse subsurface
// materials at /render/integrator, as they refuse scattering media.
TEST(Subsurface, BadInputNamesTheField) {
  const json good = sphere_scene(subsurface(0.5, 1.4));
  EXPECT_NO_THROW(load_scene(good, "/scene", SceneLoadOptions{}));
  const std::string mp = "/scene/materials/skin";
  auto with = [&](const std::string& key, const json& value) {
    json doc = good;
    doc["materials"]["skin"][key] = value;
    return doc;
  };
  test::expect_scene_error(with("subsurface_color", -0.1), mp + "/subsurface_color");
  test::expect_scene_error(with("subsurface_color", {0.5, 1.2, 0.5}), mp + "/subsurface_color/1");
  test::expect_scene_error(with("subsurface_radius", 0), mp + "/subsurface_radius");
  test::expect_scene_error(with("subsurface_radius", -1), mp + "/subsurface_radius");
  test::expect_scene_error(with("subsurface_radius", std::numeric_limits<double>::infinity()),
                           mp + "/subsurface_radius");
  test::expect_scene_error(with("subsurface_radius_scale", {1, 0, 1}), mp + "/subsurface_radius_scale/1");
  test::expect_scene_error(with("subsurface_radius_scale", {1, 1, -2}), mp + "/subsurface_radius_scale/2");
  for (double g : {1.0, -1.0, 1.5})
    test::expect_scene_error(with("subsurface_scatter_anisotropy", g), mp + "/subsurface_scatter_anisotropy",
                             "between -1");
  test::expect_scene_error(with("attenuation_color", 0.5), mp + "/attenuation_color", "subsurface");
  test::expect_scene_error(with("attenuation_distance", 2), mp + "/attenuation_distance", "subsurface");
  // An object has one interior: the material's, or its own medium.
  json both = good;
  both["objects"][0]["medium"] = {{"sigma_s", 1}};
  test::expect_scene_error(both, "/scene/objects/0/medium", "subsurface");
  // gltf_pbr's subsurface.
  json pbr = good;
  pbr["materials"]["skin"] = {{"type", "gltf_pbr"}, {"metallic", 0}, {"subsurface_weight", 1.5}};
  test::expect_scene_error(pbr, mp + "/subsurface_weight");
  pbr["materials"]["skin"]["subsurface_weight"] = 0.5;
  EXPECT_TRUE(load_scene(pbr, "/scene", SceneLoadOptions{})->has_scattering_media());
  pbr["materials"]["skin"]["subsurface_radius"] = -0.5;
  test::expect_scene_error(pbr, mp + "/subsurface_radius");
  pbr["materials"]["skin"].erase("subsurface_radius");
  pbr["materials"]["skin"]["attenuation_color"] = 0.5;
  test::expect_scene_error(pbr, mp + "/attenuation_color", "subsurface");
  pbr["materials"]["skin"].erase("attenuation_color");
  pbr["materials"]["skin"]["ior"] = 1.0;
  pbr["materials"]["skin"]["thin_walled"] = false;
  test::expect_scene_error(pbr, mp + "/ior", "subsurface");
  pbr["materials"]["skin"].erase("ior");
  pbr["objects"][0]["medium"] = {{"sigma_s", 1}};
  test::expect_scene_error(pbr, "/scene/objects/0/medium", "subsurface");
  // Thin-walled, the subsurface is diffuse transmission: no interior, no scattering medium.
  pbr["objects"][0].erase("medium");
  pbr["materials"]["skin"]["thin_walled"] = true;
  EXPECT_FALSE(load_scene(pbr, "/scene", SceneLoadOptions{})->has_scattering_media());
  pbr["materials"]["skin"]["diffuse_transmission"] = 0.5;
  test::expect_scene_error(pbr, mp + "/subsurface_weight", "diffuse_transmission");

  // Every integrator takes it: light tracing and BDPT walk subsurface media with medium vertices.
  for (const std::string name : {"bdpt", "light"}) {
    const json job = {{"scene", good}, {"render", {{"integrator", name}, {"width", 8}, {"height", 8}}}};
    EXPECT_NO_THROW(load_job(job, JobLoadOptions{})) << name;
  }
}

}  // namespace
}  // namespace tessera
