// Motion blur (render.shutter): a box shutter averages the image over an interval of the animation. An edge moving at
// constant speed across the shutter blurs into the analytic linear ramp, whether the geometry or the camera moves;
// a scene where nothing moves renders bit for bit as without a shutter, and a blurred render is deterministic.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "renderer/job.h"
#include "renderer/session.h"
#include "renderer/thread_pool.h"
#include "tests/renderer/gltf_fixture.h"

namespace tessera {
namespace {

using nlohmann::json;
using test::GltfBuilder;

// The image: 64 x 8 pixels through an orthographic camera looking down -z, 8 units wide and 1 high, so that pixel
// column i is centred at x = -4 + (i + 0.5) / 8 in the camera's frame.
constexpr int kWidth = 64, kHeight = 8;
constexpr uint32_t kSpp = 128;
double column_x(int i) {
  return -4 + (i + 0.5) * 8.0 / kWidth;
}

// Adds a LINEAR translation channel of `node` to the document's first animation: from `from` at 0 s to `to` at 2 s.
void translate(GltfBuilder& b, int node, const std::vector<float>& from, const std::vector<float>& to) {
  if (!b.doc.contains("animations")) b.doc["animations"] = {{{"channels", json::array()}, {"samplers", json::array()}}};
  json& anim = b.doc["animations"][0];
  std::vector<float> values = from;
  values.insert(values.end(), to.begin(), to.end());
  const int input = b.floats({0, 2}, "SCALAR", 1), output = b.floats(values, "VEC3", 3);
  b.doc["accessors"][input]["min"] = {0};
  b.doc["accessors"][input]["max"] = {2};
  anim["samplers"].push_back({{"input", input}, {"output", output}, {"interpolation", "LINEAR"}});
  anim["channels"].push_back(
      {{"sampler", anim["samplers"].size() - 1}, {"target", {{"node", node}, {"path", "translation"}}}});
}

// A quad covering x < 0 (and |y| < 100) of the plane z = 0 in its node's frame, of the material named "black".
int half_plane(GltfBuilder& b) {
  const int black = b.material({{"name", "black"}});
  return b.mesh({-100, -100, 0, 0, -100, 0, 0, 100, 0, -100, 100, 0}, {0, 1, 2, 0, 2, 3}, black,
                {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1});
}

// The job: the asset at scene.time 1 s against a white sky, its material "black" made a black Lambertian surface
// (every pixel is the share of its samples that see the sky); at render.fps 1, the shutter [-0.5, 0.5] frames is the
// second [0.5, 1.5] of the animation. The camera is the document's (the orthographic one above, at z = 10) unless
// `gltf_camera`.
json job(const std::string& asset, bool gltf_camera, const json& render_extra = json::object()) {
  json scene = {{"gltf", asset},
                {"time", 1.0},
                {"materials", {{"black", {{"type", "lambert"}, {"albedo", {0, 0, 0}}}}}},
                {"environment", {{"color", {1, 1, 1}}}}};
  if (!gltf_camera)
    scene["camera"] = {{"type", "orthographic"}, {"from", {0, 0, 10}}, {"to", {0, 0, 0}}, {"height", 1}};
  json render = {{"width", kWidth}, {"height", kHeight}, {"spp", kSpp}, {"seed", 3}, {"fps", 1}};
  render.update(render_extra);
  return {{"kind", "scene"}, {"scene", scene}, {"render", render}};
}

const json kShutter = {{"shutter", {{"open", -0.5}, {"close", 0.5}}}};

std::vector<float> render(const json& doc) {
  JobLoadOptions options;
  options.scene.asset_root = test::gltf_fixture_dir();
  const RenderJob loaded = load_job(doc, options);
  ThreadPool pool(2);
  RenderSession session(loaded.scene, loaded.settings, pool);
  session.run();
  return session.film().resolve();
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

// Column i's mean over the image's rows (of the red channel; the image is grey).
std::vector<double> row_profile(const std::vector<float>& image) {
  std::vector<double> profile(kWidth, 0);
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) profile[x] += image[3 * (y * kWidth + x)] / kHeight;
  return profile;
}

// The edge of the black half-plane sweeps x from -1 to 1 at constant speed while the shutter is open: a point at x
// sees the sky for the share (x + 1) / 2 of the interval, clamped to [0, 1]. Over a pixel that lies within the sweep
// the share is linear, so the pixel's box filter averages it to its value at the pixel's centre. Each of a column's
// kHeight x kSpp samples sees the sky or not: a Bernoulli trial of that mean, whose standard deviation
// sqrt(p (1 - p) / n) bounds the column's error (the stratified samples do no worse); a column is allowed 4 of them,
// and one outside the sweep, always or never covered, none at all. `what` names the case.
void expect_ramp(const std::vector<double>& profile, const std::string& what) {
  const double n = static_cast<double>(kHeight) * kSpp, half_pixel = 4.0 / kWidth;
  int ramp_columns = 0;
  for (int i = 0; i < kWidth; ++i) {
    const double x = column_x(i);
    if (x + half_pixel <= -1) {
      EXPECT_EQ(profile[i], 0) << what << ": column " << i << " (x " << x << ") is covered all the time";
    } else if (x - half_pixel >= 1) {
      EXPECT_EQ(profile[i], 1) << what << ": column " << i << " (x " << x << ") is never covered";
    } else if (x - half_pixel >= -1 && x + half_pixel <= 1) {
      const double p = (x + 1) / 2, sigma = std::sqrt(p * (1 - p) / n);
      EXPECT_NEAR(profile[i], p, 4 * sigma) << what << ": column " << i << " (x " << x << ") against the ramp";
      ++ramp_columns;
    }
  }
  EXPECT_EQ(ramp_columns, 16) << what << ": the sweep is 2 units, 16 columns of 1/8";
}

// The half-plane moved along x from -2 at 0 s to 2 at 2 s (1 to -1 while the shutter is open at 1 s, at 2 units a
// second); `moving` false: held at x = 0.
std::string moving_half_plane(bool moving) {
  GltfBuilder b;
  const int node = b.node({{"mesh", half_plane(b)}}, true);
  translate(b, node, {moving ? -2.0f : 0.0f, 0, 0}, {moving ? 2.0f : 0.0f, 0, 0});
  const std::string name = moving ? "half_plane_moving" : "half_plane_held";
  b.write(test::gltf_fixture_dir(), name);
  return name + ".gltf";
}

TEST(MotionBlur, AnEdgeMovingAtConstantSpeedBlursIntoTheLinearRamp) {
  const std::string asset = moving_half_plane(true);
  for (int steps : {2, 8}) {
    json extra = kShutter;
    extra["shutter"]["steps"] = steps;
    expect_ramp(row_profile(render(job(asset, false, extra))), std::to_string(steps) + " time steps");
  }
  // Without a shutter the edge is sharp at x = 0: the frame's pose, half the image covered.
  const std::vector<double> sharp = row_profile(render(job(asset, false)));
  EXPECT_EQ(sharp[kWidth / 2 - 1], 0);
  EXPECT_EQ(sharp[kWidth / 2], 1);
}

// The camera's own motion: a glTF orthographic camera moved along x from 2 at 0 s to -2 at 2 s (1 to -1 while the
// shutter is open) over a still half-plane; in the camera's frame the edge sweeps from -1 to 1, the same ramp.
TEST(MotionBlur, AnAnimatedCameraBlurs) {
  GltfBuilder b;
  b.node({{"mesh", half_plane(b)}}, true);
  b.doc["cameras"] = {
      {{"type", "orthographic"}, {"orthographic", {{"xmag", 4}, {"ymag", 0.5}, {"znear", 0.1}, {"zfar", 100}}}}};
  const int camera = b.node({{"camera", 0}, {"translation", {0, 0, 10}}}, true);
  translate(b, camera, {2, 0, 10}, {-2, 0, 10});
  b.write(test::gltf_fixture_dir(), "camera_moving");
  expect_ramp(row_profile(render(job("camera_moving.gltf", true, kShutter))), "the camera moving");
  const std::vector<double> sharp = row_profile(render(job("camera_moving.gltf", true)));
  EXPECT_EQ(sharp[kWidth / 2 - 1], 0);
  EXPECT_EQ(sharp[kWidth / 2], 1);
}

// Nothing that the image shows moves: the shutter changes no bit. Both an animation that holds its node still (no
// time is drawn) and a scene whose only moving object is out of sight (times are drawn, from the sampler's reserved
// dimension, which moves no other number). A grey Lambertian surface under the sky, so that paths bounce and draw.
TEST(MotionBlur, AStillSceneRendersBitIdenticalWithAndWithoutAShutter) {
  const json grey = {{"black", {{"type", "lambert"}, {"albedo", {0.5, 0.5, 0.5}}}}};
  json held = job(moving_half_plane(false), false);
  held["scene"]["materials"] = grey;
  json held_blurred = held;
  held_blurred["render"].update(kShutter);
  EXPECT_TRUE(same_bits(render(held), render(held_blurred))) << "a held animation";

  GltfBuilder b;
  b.node({{"mesh", half_plane(b)}}, true);
  const int hidden = b.node({{"mesh", b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, -1)}}, true);
  translate(b, hidden, {-50, 0, -50}, {-40, 0, -50});  // under the half-plane, behind what the camera sees
  b.write(test::gltf_fixture_dir(), "hidden_moving");
  json out_of_sight = job("hidden_moving.gltf", false);
  out_of_sight["scene"]["materials"] = grey;
  json out_of_sight_blurred = out_of_sight;
  out_of_sight_blurred["render"].update(kShutter);
  EXPECT_TRUE(same_bits(render(out_of_sight), render(out_of_sight_blurred))) << "a moving object out of sight";
}

// Two blurred renders, of the path tracer and of the bidirectional one (whose light subpaths share the camera
// sample's time), are the same bits.
TEST(MotionBlur, BlurredRendersAreDeterministic) {
  const std::string asset = moving_half_plane(true);
  for (const char* integrator : {"path", "bdpt"}) {
    json extra = kShutter;
    extra["integrator"] = integrator;
    json doc = job(asset, false, extra);
    // bdpt needs a perspective camera.
    doc["scene"]["camera"] = {{"from", {0, 0, 10}}, {"to", {0, 0, 0}}, {"fov_deg", 30}};
    const std::vector<float> first = render(doc), second = render(doc);
    EXPECT_TRUE(same_bits(first, second)) << integrator;
    const std::vector<double> profile = row_profile(first);
    EXPECT_GT(profile[kWidth / 2 + 4], profile[kWidth / 2 - 4]) << integrator << ": the ramp rises";
  }
}

}  // namespace
}  // namespace tessera
