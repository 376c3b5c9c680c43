// glTF animations (glTF 2.0, 3.11 "Animations"; Appendix C "Animation Sampler Interpolation Modes"): samplers
// against the specification's formulas, each case chosen so that a plausible mistake fails it; nodes, morph weights,
// skins, cameras and lights posed at a time through the importer; the choice of animation, and what is refused.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <numbers>
#include <optional>

#include "renderer/gltf/internal.h"
#include "renderer/job.h"
#include "renderer/session.h"
#include "renderer/thread_pool.h"
#include "tests/renderer/gltf_fixture.h"

namespace tessera {
namespace {

using gltf::AnimationSampler;
using nlohmann::json;
using test::GltfBuilder;
using Interpolation = AnimationSampler::Interpolation;

std::filesystem::path fixture_dir() {
  return test::gltf_fixture_dir();
}

AnimationSampler sampler(Interpolation interpolation, std::vector<float> times, std::vector<float> values, int width,
                         bool rotation = false) {
  AnimationSampler s;
  s.interpolation = interpolation;
  s.times = std::move(times);
  s.values = std::move(values);
  s.width = width;
  s.rotation = rotation;
  return s;
}

std::vector<double> at(const AnimationSampler& s, double t) {
  std::vector<double> out(static_cast<size_t>(s.width));
  s.evaluate(t, out.data());
  return out;
}

// The unit quaternion (x, y, z, w) of a rotation by `deg` degrees about +z.
std::vector<float> about_z(double deg) {
  const double h = deg * std::numbers::pi / 360;
  return {0, 0, static_cast<float>(std::sin(h)), static_cast<float>(std::cos(h))};
}

// The angle in degrees, about +z, of the rotation by unit quaternion q (q and -q alike).
double z_angle(const std::vector<double>& q) {
  const double sign = q[3] < 0 ? -1 : 1;
  return 2 * std::atan2(sign * q[2], sign * q[3]) * 180 / std::numbers::pi;
}

// LINEAR: (1 - u) v_k + u v_k+1 with u = (t - t_k) / (t_k+1 - t_k). Keyframes at 1 s and 3 s: a u that is not
// divided by the interval (or not measured from t_k) gives another value at 1.5 s; outside the keyframes the first
// and the last value hold (no extrapolation).
TEST(GltfAnimation, LinearFollowsTheSpecificationsFormula) {
  const AnimationSampler s = sampler(Interpolation::kLinear, {1, 3}, {0, 10, -2, 4, 0, 6}, 3);
  const std::vector<double> mid = at(s, 1.5);  // u = 0.25
  EXPECT_NEAR(mid[0], 0.75 * 0 + 0.25 * 4, 1e-6);
  EXPECT_NEAR(mid[1], 0.75 * 10 + 0.25 * 0, 1e-6);
  EXPECT_NEAR(mid[2], 0.75 * -2 + 0.25 * 6, 1e-6);
  EXPECT_EQ(at(s, 0), (std::vector<double>{0, 10, -2}));
  EXPECT_EQ(at(s, -5), (std::vector<double>{0, 10, -2}));
  EXPECT_EQ(at(s, 3), (std::vector<double>{4, 0, 6}));
  EXPECT_EQ(at(s, 7), (std::vector<double>{4, 0, 6}));
}

// STEP: the value of the keyframe at or before t, not the nearest one (0.99 s is still the first keyframe's).
TEST(GltfAnimation, StepHoldsTheKeyframeAtOrBeforeTheTime) {
  const AnimationSampler s = sampler(Interpolation::kStep, {0, 1, 2}, {5, 7, 9}, 1);
  EXPECT_EQ(at(s, 0.99)[0], 5);
  EXPECT_EQ(at(s, 1)[0], 7);
  EXPECT_EQ(at(s, 1.5)[0], 7);
  EXPECT_EQ(at(s, 1.999)[0], 7);
  EXPECT_EQ(at(s, 2)[0], 9);
  EXPECT_EQ(at(s, 30)[0], 9);
  EXPECT_EQ(at(s, -1)[0], 5);
}

// CUBICSPLINE: p(u) = (2u^3 - 3u^2 + 1) v_k + td (u^3 - 2u^2 + u) b_k + (-2u^3 + 3u^2) v_k+1 + td (u^3 - u^2) a_k+1,
// each keyframe stored as in-tangent a, value v, out-tangent b, td = t_k+1 - t_k. The interval here is 2 s, so
// tangents not scaled by it give half the bulge; at and beyond the keyframes the values (not the tangents) hold.
TEST(GltfAnimation, CubicSplineScalesTangentsByTheKeyframeInterval) {
  // Two components: (in, value, out) per keyframe, keyframes at 1 s and 3 s.
  const AnimationSampler s = sampler(Interpolation::kCubicSpline, {1, 3},
                                     {/*a0*/ 9, 9, /*v0*/ 0, 1, /*b0*/ 1, 0.5f,  //
                                      /*a1*/ -1, 2, /*v1*/ 0, 3, /*b1*/ 9, 9},
                                     2);
  auto hermite = [](double u, double v0, double b0, double v1, double a1, double td) {
    const double u2 = u * u, u3 = u2 * u;
    return (2 * u3 - 3 * u2 + 1) * v0 + td * (u3 - 2 * u2 + u) * b0 + (-2 * u3 + 3 * u2) * v1 + td * (u3 - u2) * a1;
  };
  for (double t : {1.5, 2.0, 2.7}) {
    const double u = (t - 1) / 2;
    const std::vector<double> v = at(s, t);
    EXPECT_NEAR(v[0], hermite(u, 0, 1, 0, -1, 2), 1e-6) << "t " << t;
    EXPECT_NEAR(v[1], hermite(u, 1, 0.5, 3, 2, 2), 1e-6) << "t " << t;
  }
  EXPECT_NEAR(at(s, 2)[0], 0.5, 1e-6);  // by hand: 2 (0.125 * 1) + 2 (-0.125 * -1); unscaled tangents give 0.25
  EXPECT_EQ(at(s, 1), (std::vector<double>{0, 1}));
  EXPECT_EQ(at(s, 0), (std::vector<double>{0, 1}));
  EXPECT_EQ(at(s, 3), (std::vector<double>{0, 3}));
  EXPECT_EQ(at(s, 4), (std::vector<double>{0, 3}));
  // A rotation's spline is normalised after (the spline of unit quaternions is not unit between keyframes).
  std::vector<float> q;
  for (const std::vector<float>& part : {std::vector<float>{0, 0, 0, 0}, about_z(0), std::vector<float>{0, 0, 1, 0},
                                         std::vector<float>{0, 0, 0, 0}, about_z(90), std::vector<float>{0, 0, 0, 0}})
    q.insert(q.end(), part.begin(), part.end());
  const std::vector<double> r = at(sampler(Interpolation::kCubicSpline, {0, 1}, q, 4, true), 0.5);
  EXPECT_NEAR(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3], 1, 1e-9);
}

// LINEAR rotations: slerp (Shoemake 1985; glTF 2.0, Appendix C): a quarter of the way from 0 to 90 degrees is 22.5
// degrees (a normalised linear blend gives about 20.6); the same rotation stored as -q is still 90 degrees away, not
// 270 (slerp must take the shorter arc).
TEST(GltfAnimation, SlerpTakesTheShortArcAtConstantSpeed) {
  std::vector<float> keys = about_z(0);
  const std::vector<float> quarter = about_z(90);
  keys.insert(keys.end(), quarter.begin(), quarter.end());
  const AnimationSampler s = sampler(Interpolation::kLinear, {0, 1}, keys, 4, true);
  EXPECT_NEAR(z_angle(at(s, 0.25)), 22.5, 1e-6);
  EXPECT_NEAR(z_angle(at(s, 0.5)), 45, 1e-6);
  std::vector<float> negated = about_z(0);
  for (float c : quarter) negated.push_back(-c);
  const AnimationSampler n = sampler(Interpolation::kLinear, {0, 1}, negated, 4, true);
  EXPECT_NEAR(z_angle(at(n, 0.5)), 45, 1e-6) << "the long way round gives -135";
  EXPECT_NEAR(z_angle(at(n, 0.25)), 22.5, 1e-6);
  const std::vector<double> r = at(n, 0.3);
  EXPECT_NEAR(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3], 1, 1e-12);
}

// ---- Through the importer: fixtures with animations ----

// Adds a sampler (input times, output values) to animation `a` of the document, and a channel driving `path` of
// `node` with it.
void channel(GltfBuilder& b, size_t a, int node, const std::string& path, const std::string& interpolation,
             const std::vector<float>& times, const std::vector<float>& values, const std::string& type, int comps) {
  if (!b.doc.contains("animations")) b.doc["animations"] = json::array();
  while (b.doc["animations"].size() <= a)
    b.doc["animations"].push_back({{"channels", json::array()}, {"samplers", json::array()}});
  json& anim = b.doc["animations"][a];
  const int input = b.floats(times, "SCALAR", 1), output = b.floats(values, type, comps);
  b.doc["accessors"][input]["min"] = {times.front()};  // required of a sampler's input (glTF 2.0, 5.4)
  b.doc["accessors"][input]["max"] = {times.back()};
  anim["samplers"].push_back({{"input", input}, {"output", output}, {"interpolation", interpolation}});
  anim["channels"].push_back({{"sampler", anim["samplers"].size() - 1}, {"target", {{"node", node}, {"path", path}}}});
}

GltfBuilder one_triangle() {
  GltfBuilder b;
  const int mesh = b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, -1);
  b.node({{"mesh", mesh}}, true);
  return b;
}

GltfImport import_at(const std::filesystem::path& path, Scene& scene, std::optional<double> time,
                     const std::string& name = "", int index = -1) {
  GltfImportOptions options;
  options.animate = time.has_value() || !name.empty() || index >= 0;
  options.time = time.value_or(0);
  options.animation_name = name;
  options.animation_index = index;
  options.animation_pointer = "/scene/animation";
  return import_gltf(path, "/scene/gltf", scene, options);
}

void expect_near(const Vec3& got, const Vec3& want, const std::string& what) {
  EXPECT_NEAR(got.x, want.x, 1e-5) << what;
  EXPECT_NEAR(got.y, want.y, 1e-5) << what;
  EXPECT_NEAR(got.z, want.z, 1e-5) << what;
}

// A node's translation (LINEAR), rotation (LINEAR: slerp) and scale (STEP) at a time, composed as T * R * S (glTF
// 2.0, 3.5.2); before the first keyframe and after the last, the first and last values.
TEST(GltfAnimation, TranslationRotationAndScaleChannelsPoseTheNode) {
  GltfBuilder b = one_triangle();
  std::vector<float> rot = about_z(0), quarter = about_z(90);
  rot.insert(rot.end(), quarter.begin(), quarter.end());
  channel(b, 0, 0, "translation", "LINEAR", {0, 2}, {0, 0, 0, 4, 0, 0}, "VEC3", 3);
  channel(b, 0, 0, "rotation", "LINEAR", {0, 2}, rot, "VEC4", 4);
  channel(b, 0, 0, "scale", "STEP", {0, 0.25f}, {1, 1, 1, 2, 2, 2}, "VEC3", 3);
  const auto path = b.write(fixture_dir(), "trs");
  const double c = std::cos(22.5 * std::numbers::pi / 180), s = std::sin(22.5 * std::numbers::pi / 180);
  struct Case {
    double t;
    Vec3 vertex1;  // where local (1, 0, 0) lands
  };
  for (const Case& k : {Case{0.5, Vec3(static_cast<float>(1 + 2 * c), static_cast<float>(2 * s), 0)},
                        Case{-1, Vec3(1, 0, 0)}, Case{10, Vec3(4, 2, 0)}}) {
    Scene scene;
    const GltfImport imported = import_at(path, scene, k.t);
    EXPECT_TRUE(imported.warnings.empty()) << imported.warnings.front();
    ASSERT_EQ(scene.meshes.size(), 1u);
    expect_near(scene.meshes[0].positions[1], k.vertex1, "t " + std::to_string(k.t));
  }
  // Without a time: the node as stated, and a warning that the animation was not applied.
  Scene still;
  const GltfImport imported = import_at(path, still, std::nullopt);
  expect_near(still.meshes[0].positions[1], Vec3(1, 0, 0), "no time");
  ASSERT_EQ(imported.warnings.size(), 1u);
  EXPECT_NE(imported.warnings[0].find("animation is not applied"), std::string::npos) << imported.warnings[0];
}

// A morphed mesh at a keyframe and between two: base + sum of weight_k * displacement_k (glTF 2.0, 3.7.2.2), the
// weights the channel's (LINEAR, two per keyframe). Another node drawing the same mesh keeps its default weights.
TEST(GltfAnimation, MorphWeightsAtAKeyframeMoveTheVertices) {
  GltfBuilder b = one_triangle();
  const int up = b.floats({0, 1, 0, 0, 1, 0, 0, 1, 0}, "VEC3", 3),
            right = b.floats({2, 0, 0, 0, 0, 0, 0, 0, 0}, "VEC3", 3);
  b.doc["meshes"][0]["primitives"][0]["targets"] = {{{"POSITION", up}}, {{"POSITION", right}}};
  b.doc["meshes"][0]["weights"] = {0, 0};
  b.node({{"mesh", 0}, {"translation", {0, 0, -10}}}, true);  // the same mesh, not animated
  channel(b, 0, 0, "weights", "LINEAR", {0, 1, 2}, {0, 0, 1, 0.5f, 0, 1}, "SCALAR", 1);
  const auto path = b.write(fixture_dir(), "morph_animated");
  struct Case {
    double t;
    Vec3 v0, v2;
  };
  // t = 1: weights (1, 0.5): v0 = (0, 0, 0) + (0, 1, 0) + 0.5 (2, 0, 0); v2 = (0, 1, 0) + (0, 1, 0).
  // t = 1.5: weights (0.5, 0.75): v0 = 0.5 (0, 1, 0) + 0.75 (2, 0, 0); v2 = (0, 1.5, 0).
  for (const Case& k : {Case{1, Vec3(1, 1, 0), Vec3(0, 2, 0)}, Case{1.5, Vec3(1.5, 0.5, 0), Vec3(0, 1.5, 0)}}) {
    Scene scene;
    import_at(path, scene, k.t);
    const Mesh* animated = nullptr;
    const Mesh* shared = nullptr;
    for (const Mesh& m : scene.meshes) (m.prototype ? shared : animated) = &m;
    ASSERT_TRUE(animated && shared) << "the animated node's own mesh and the other node's shared one";
    expect_near(animated->positions[0], k.v0, "t " + std::to_string(k.t));
    expect_near(animated->positions[2], k.v2, "t " + std::to_string(k.t));
    expect_near(shared->positions[0], Vec3(0, 0, 0), "the node that is not animated");
  }
}

// A skinned mesh at a keyframe: its joints posed by the animation (joint 0 turned a quarter about z by a STEP
// channel, joint 1, its child, moved along its parent's x by a LINEAR one), each vertex the WEIGHTS_0 blend of its
// joints' world transforms times their inverse bind matrices (glTF 2.0, 3.7.3). At the first keyframe, the bind pose.
TEST(GltfAnimation, ASkinnedMeshAtAKeyframeFollowsItsAnimatedJoints) {
  GltfBuilder b = one_triangle();
  // Vertex 0 follows joint 0 alone, vertex 1 joint 1 alone, vertex 2 half of each.
  const int joints = b.indices16({0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0});  // unsigned shorts, as VEC4
  b.doc["accessors"][joints]["type"] = "VEC4";
  b.doc["accessors"][joints]["count"] = 3;
  const int weights = b.floats({1, 0, 0, 0, 1, 0, 0, 0, 0.5, 0.5, 0, 0}, "VEC4", 4);
  b.doc["meshes"][0]["primitives"][0]["attributes"]["JOINTS_0"] = joints;
  b.doc["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_0"] = weights;
  // Joint 1's inverse bind matrix undoes a bind at x = 1.
  const int ibm = b.floats({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0,  0, 0, 1,  //
                            1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1},
                           "MAT4", 16);
  b.doc["nodes"][0]["skin"] = 0;
  const int j1 = b.node({{"translation", {10, 0, 0}}}, false);
  const int j0 = b.node({{"translation", {0, 0, -5}}, {"children", {j1}}}, true);
  b.doc["skins"] = {{{"joints", {j0, j1}}, {"inverseBindMatrices", ibm}}};
  std::vector<float> rot = about_z(0), quarter = about_z(90);
  rot.insert(rot.end(), quarter.begin(), quarter.end());
  channel(b, 0, j0, "rotation", "STEP", {0, 1}, rot, "VEC4", 4);
  channel(b, 0, j1, "translation", "LINEAR", {0, 1}, {10, 0, 0, 20, 0, 0}, "VEC3", 3);
  const auto path = b.write(fixture_dir(), "skin_animated");
  Scene scene;
  import_at(path, scene, 1.0);
  ASSERT_EQ(scene.meshes.size(), 1u);
  const std::vector<Vec3>& p = scene.meshes[0].positions;
  // Joint 0 = T(0, 0, -5) R, joint 1 = joint 0 T(20, 0, 0), R a quarter turn about z: (x, y) -> (-y, x).
  expect_near(p[0], Vec3(0, 0, -5), "vertex 0: R (0, 0, 0) + (0, 0, -5)");
  expect_near(p[1], Vec3(0, 20, -5), "vertex 1: (1, 0, 0) - (1, 0, 0) + (20, 0, 0), turned, + (0, 0, -5)");
  expect_near(p[2], Vec3(-1, 9.5, -5), "vertex 2: half (-1, 0, -5) and half R (19, 1, 0) + (0, 0, -5)");
  Scene bind;
  import_at(path, bind, 0.0);
  expect_near(bind.meshes[0].positions[1], Vec3(10, 0, -5), "t 0: vertex 1");
  expect_near(bind.meshes[0].positions[2], Vec3(4.5, 1, -5), "t 0: vertex 2");
}

// A camera and a KHR_lights_punctual light follow their animated nodes: the camera moved along z (LINEAR) and turned
// half round y (STEP) to look down +z, the light moved.
TEST(GltfAnimation, CamerasAndLightsFollowTheirAnimatedNodes) {
  GltfBuilder b = one_triangle();
  b.doc["cameras"] = {{{"type", "perspective"}, {"perspective", {{"yfov", 0.5}, {"znear", 0.1}}}}};
  const int cam = b.node({{"camera", 0}}, true);
  b.doc["extensionsUsed"] = {"KHR_lights_punctual"};
  b.doc["extensions"] = {{"KHR_lights_punctual", {{"lights", {{{"type", "point"}, {"intensity", 1}}}}}}};
  const int light =
      b.node({{"translation", {0, 5, 0}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}, true);
  channel(b, 0, cam, "translation", "LINEAR", {0, 4}, {0, 0, 0, 0, 0, 8}, "VEC3", 3);
  channel(b, 0, cam, "rotation", "STEP", {0, 0.5f}, {0, 0, 0, 1, 0, 1, 0, 0}, "VEC4", 4);
  channel(b, 0, light, "translation", "LINEAR", {0, 1}, {0, 5, 0, 2, 5, 0}, "VEC3", 3);
  const auto path = b.write(fixture_dir(), "camera_animated");
  Scene scene;
  const GltfImport imported = import_at(path, scene, 1.0);
  ASSERT_EQ(imported.cameras.size(), 1u);
  expect_near(imported.cameras[0].desc.from, Vec3(0, 0, 2), "camera position at 1 s");
  expect_near(imported.cameras[0].desc.to - imported.cameras[0].desc.from, Vec3(0, 0, 1), "camera direction");
  ASSERT_EQ(imported.lights.size(), 1u);
  expect_near(imported.lights[0].position, Vec3(2, 5, 0), "light position at 1 s");
}

// Which animation poses the nodes: the first by default, another by name or index; the channels of the others are
// not applied, and a warning says which one was.
TEST(GltfAnimation, OneAnimationIsChosenAndTheOthersIgnored) {
  GltfBuilder b = one_triangle();
  channel(b, 0, 0, "translation", "LINEAR", {0}, {1, 0, 0}, "VEC3", 3);
  channel(b, 1, 0, "translation", "LINEAR", {0}, {0, 2, 0}, "VEC3", 3);
  b.doc["animations"][0]["name"] = "walk";
  b.doc["animations"][1]["name"] = "run";
  const auto path = b.write(fixture_dir(), "two_animations");
  struct Case {
    std::string name;
    int index;
    Vec3 origin;
  };
  for (const Case& k : {Case{"", -1, Vec3(1, 0, 0)}, Case{"run", -1, Vec3(0, 2, 0)}, Case{"", 1, Vec3(0, 2, 0)},
                        Case{"walk", -1, Vec3(1, 0, 0)}}) {
    Scene scene;
    const GltfImport imported = import_at(path, scene, 0.0, k.name, k.index);
    expect_near(scene.meshes[0].positions[0], k.origin, "animation \"" + k.name + "\" " + std::to_string(k.index));
    ASSERT_EQ(imported.warnings.size(), 1u);
    EXPECT_NE(imported.warnings[0].find("the asset has 2 animations; only animation"), std::string::npos)
        << imported.warnings[0];
  }
}

// scene.animation naming an animation the asset does not have, or an index past its animations, is refused at
// /scene/animation (a 422 from the daemon), with the closest name; so is scene.time without a glTF asset.
TEST(GltfAnimation, AnUnknownAnimationIsRefusedNamingTheField) {
  GltfBuilder b = one_triangle();
  channel(b, 0, 0, "translation", "STEP", {0}, {1, 0, 0}, "VEC3", 3);
  b.doc["animations"][0]["name"] = "walk";
  b.write(fixture_dir(), "walk");
  one_triangle().write(fixture_dir(), "still");
  JobLoadOptions opts;
  opts.scene.asset_root = fixture_dir();
  auto refusal = [&](const json& scene) -> std::pair<std::string, std::string> {
    const json job = {{"kind", "scene"}, {"scene", scene}, {"render", {{"width", 8}, {"height", 8}, {"spp", 1}}}};
    try {
      load_job(job, opts);
    } catch (const SceneError& e) {
      return {e.pointer(), e.what()};
    }
    return {"", "accepted"};
  };
  auto [where, what] = refusal({{"gltf", "walk.gltf"}, {"animation", "wlak"}});
  EXPECT_EQ(where, "/scene/animation");
  EXPECT_NE(what.find("no animation \"wlak\" (did you mean \"walk\"?)"), std::string::npos) << what;
  std::tie(where, what) = refusal({{"gltf", "walk.gltf"}, {"animation", 1}});
  EXPECT_EQ(where, "/scene/animation");
  EXPECT_NE(what.find("there is no animation 1"), std::string::npos) << what;
  std::tie(where, what) = refusal({{"gltf", "still.gltf"}, {"animation", "walk"}});
  EXPECT_EQ(where, "/scene/animation");
  EXPECT_NE(what.find("has no animations"), std::string::npos) << what;
  std::tie(where, what) = refusal({{"gltf", "walk.gltf"}, {"animation", -1}});
  EXPECT_EQ(where, "/scene/animation");
  std::tie(where, what) =
      refusal({{"objects", json::array()}, {"camera", {{"from", {0, 0, 1}}, {"to", {0, 0, 0}}}}, {"time", 1}});
  EXPECT_EQ(where, "/scene/time");
  std::tie(where, what) = refusal({{"gltf", "walk.gltf"}, {"animation", "walk"}, {"time", 0.5}});
  EXPECT_EQ(what, "accepted");
}

// Keyframes that break the specification are refused naming the animation's part, at the asset's pointer: times that
// do not increase, an output whose count does not fit the input's (CUBICSPLINE needs three per keyframe), an unknown
// interpolation, a node that does not exist. A channel on a node with a matrix (which the specification forbids) and
// one animating the weights of a mesh without morph targets are warnings, and the rest of the animation applies.
TEST(GltfAnimation, MalformedKeyframesAreRefusedOrWarned) {
  auto refusal = [](GltfBuilder b, const std::string& name) -> std::string {
    const auto path = b.write(fixture_dir(), name);
    Scene scene;
    try {
      import_at(path, scene, 0.5);
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), "/scene/gltf") << name;
      return e.what();
    }
    return "accepted";
  };
  GltfBuilder b = one_triangle();
  channel(b, 0, 0, "translation", "LINEAR", {0, 1, 1}, {0, 0, 0, 1, 0, 0, 2, 0, 0}, "VEC3", 3);
  EXPECT_NE(refusal(b, "times_not_increasing")
                .find("animation 0 sampler 0: its keyframe times are not strictly "
                      "increasing (at keyframe 2)"),
            std::string::npos);
  b = one_triangle();
  channel(b, 0, 0, "translation", "CUBICSPLINE", {0, 1}, {0, 0, 0, 1, 0, 0}, "VEC3", 3);
  EXPECT_NE(refusal(b, "cubic_count")
                .find("its output holds 6 values where 2 keyframes of translation (in-tangent, "
                      "value, out-tangent) need 18"),
            std::string::npos);
  b = one_triangle();
  channel(b, 0, 0, "scale", "SMOOTH", {0}, {1, 1, 1}, "VEC3", 3);
  EXPECT_NE(refusal(b, "unknown_interpolation").find("the unknown interpolation \"SMOOTH\""), std::string::npos);
  b = one_triangle();
  channel(b, 0, 7, "scale", "STEP", {0}, {1, 1, 1}, "VEC3", 3);
  EXPECT_NE(refusal(b, "no_such_node").find("targets node 7, which does not exist"), std::string::npos);

  b = one_triangle();
  b.node({{"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}}}, true);
  channel(b, 0, 1, "translation", "STEP", {0}, {5, 0, 0}, "VEC3", 3);
  channel(b, 0, 0, "weights", "STEP", {0}, {1}, "SCALAR", 1);
  channel(b, 0, 0, "translation", "STEP", {0}, {0, 3, 0}, "VEC3", 3);
  const auto path = b.write(fixture_dir(), "warned_channels");
  Scene scene;
  const GltfImport imported = import_at(path, scene, 0.5);
  expect_near(scene.meshes[0].positions[0], Vec3(0, 3, 0), "the channel that is well-formed applies");
  std::string all;
  for (const std::string& w : imported.warnings) all += w + "\n";
  EXPECT_NE(all.find("animates node 1, which has a matrix"), std::string::npos) << all;
  EXPECT_NE(all.find("whose mesh has no morph targets"), std::string::npos) << all;
}

// An asset without animations renders bit-identical with and without an explicit scene.time 0: a still without a
// time is the asset as stated, and so is any time of an asset that nothing animates. The Duck (examples/), and a
// fixture whose rotation is not quite a unit quaternion (posing it normalised would scale it) and whose mesh two
// nodes share (traced as instances).
TEST(GltfAnimation, AnAssetWithoutAnimationsRendersTheSameWithATime) {
  GltfBuilder b;
  // Lit by the white environment an asset without lights gets; not emissive, so that the shared mesh is instanced.
  const int red = b.material({{"pbrMetallicRoughness", {{"baseColorFactor", {1, 0.2, 0.1, 1}}}}});
  const int mesh = b.mesh({-1, -1, 0, 1, -1, 0, 0, 1, 0}, {0, 1, 2}, red);
  b.node({{"mesh", mesh}, {"rotation", {0, 0, 0.6, 0.81}}, {"translation", {-1, 0, 0}}}, true);
  b.node({{"mesh", mesh}, {"translation", {1.5, 0, 0}}, {"scale", {0.5, 0.5, 0.5}}}, true);
  b.write(fixture_dir(), "no_animations");
  auto render = [](const std::filesystem::path& root, const json& scene) {
    JobLoadOptions opts;
    opts.scene.asset_root = root;
    const json job = {{"kind", "scene"}, {"scene", scene}, {"render", {{"width", 32}, {"height", 24}, {"spp", 4}}}};
    RenderJob rj = load_job(job, opts);
    ThreadPool pool(2);
    RenderSession session(rj.scene, rj.settings, pool);
    session.run();
    return session.film().resolve();
  };
  const json camera = {{"from", {0, 0, 6}}, {"to", {0, 0, 0}}, {"fov_deg", 50}};
  for (const auto& [root, scene] : std::vector<std::pair<std::filesystem::path, json>>{
           {"examples/duck", {{"gltf", "Duck.glb"}}},
           {fixture_dir(), {{"gltf", "no_animations.gltf"}, {"camera", camera}}}}) {
    json timed = scene;
    timed["time"] = 0;
    const std::vector<float> plain = render(root, scene), at_zero = render(root, timed);
    ASSERT_EQ(plain.size(), at_zero.size());
    EXPECT_EQ(std::memcmp(plain.data(), at_zero.data(), plain.size() * sizeof(float)), 0) << scene.dump();
    double sum = 0;
    for (float v : plain) sum += v;
    EXPECT_GT(sum, 0) << "something is visible: " << scene.dump();
  }
}

}  // namespace
}  // namespace tessera
