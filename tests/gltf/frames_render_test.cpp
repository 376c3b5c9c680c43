// Frames of a glTF animation (render.frames): a frame renders bit-identical to the still at its time (scene.time =
// f / fps + time_offset) whatever range it is asked in, and a range is refused, naming the field, where it cannot
// be rendered (no animation, an unknown one, a material job, a time of its own).
#include <gtest/gtest.h>

#include <cstring>

#include "renderer/frames.h"
#include "renderer/job.h"
#include "renderer/scene_error.h"
#include "renderer/session.h"
#include "renderer/thread_pool.h"

namespace tessera {
namespace {

using nlohmann::json;

const char* kCubeRoot = "examples/spinning_cube";

json cube_job(const json& render_extra, const json& scene_extra = json::object()) {
  json job = {{"kind", "scene"},
              {"scene", {{"gltf", "SpinningCube.glb"}}},
              {"render", {{"width", 48}, {"height", 27}, {"spp", 4}, {"seed", 7}}}};
  job["render"].update(render_extra);
  job["scene"].update(scene_extra);
  return job;
}

std::vector<float> render(const std::shared_ptr<Scene>& scene, const RenderSettings& settings) {
  ThreadPool pool(2);
  RenderSession session(scene, settings, pool);
  session.run();
  return session.film().resolve();
}

// Frame `frame` of the job's range, as the command line renders each frame.
std::vector<float> render_frame(const json& job, int64_t frame) {
  JobLoadOptions options;
  options.scene.asset_root = kCubeRoot;
  const RenderJob checked = load_job(job, options);
  return render(load_frame_scene(job, checked.settings, frame, options.scene), checked.settings);
}

std::vector<float> render_still(const json& job) {
  JobLoadOptions options;
  options.scene.asset_root = kCubeRoot;
  const RenderJob still = load_job(job, options);
  return render(still.scene, still.settings);
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

TEST(FrameRender, AFrameOfARangeIsTheStillAtItsTime) {
  const double offset = 0.125;
  const json range = {{"frames", {{"start", 1}, {"end", 48}, {"step", 4}}}, {"fps", 24}};
  const std::vector<float> in_range = render_frame(cube_job(range, {{"time_offset", offset}}), 9);
  const std::vector<float> alone =
      render_frame(cube_job({{"frames", {{"start", 9}, {"end", 9}}}}, {{"time_offset", offset}}), 9);
  const std::vector<float> still = render_still(cube_job(json::object(), {{"time", 9 / 24.0 + offset}}));
  EXPECT_TRUE(same_bits(in_range, still)) << "frame 9 of 1-48:4 differs from the still at 9/24 + 0.125 s";
  EXPECT_TRUE(same_bits(alone, still)) << "frame 9 of 9-9 differs from the still at 9/24 + 0.125 s";
  // A range of one frame loads as the still at its time (the daemon renders it so).
  JobLoadOptions options;
  options.scene.asset_root = kCubeRoot;
  const RenderJob one =
      load_job(cube_job({{"frames", {{"start", 9}, {"end", 9}}}}, {{"time_offset", offset}}), options);
  EXPECT_TRUE(same_bits(render(one.scene, one.settings), still));
  // The cube moves: another frame is another image, so the comparisons above compare something.
  EXPECT_FALSE(same_bits(render_frame(cube_job(range), 13), render_frame(cube_job(range), 9)));
}

TEST(FrameRender, RangesThatCannotBeRenderedAreRefusedNamingTheField) {
  struct Case {
    const char* what;
    json job;
    const char* root;
    const char* pointer;
  };
  const json frames = {{"frames", {{"start", 1}, {"end", 3}}}};
  const json box_job = {{"kind", "scene"}, {"scene", {{"gltf", "Box.glb"}}}, {"render", frames}};
  const json spheres_job = {
      {"kind", "scene"},
      {"scene",
       {{"materials", {{"grey", {{"type", "lambert"}, {"albedo", {0.5, 0.5, 0.5}}}}}},
        {"objects", {{{"shape", "sphere"}, {"center", {0, 0, 0}}, {"radius", 1}, {"material", "grey"}}}},
        {"camera", {{"from", {0, 0, 5}}, {"to", {0, 0, 0}}}}}},
      {"render", frames}};
  const json material_job = {
      {"kind", "material"}, {"material", {{"type", "lambert"}, {"albedo", {0.5, 0.5, 0.5}}}}, {"render", frames}};
  const Case cases[] = {
      {"an asset without animations", box_job, "examples/box", "/render/frames"},
      {"a scene without a glTF asset", spheres_job, ".", "/render/frames"},
      {"a material job", material_job, ".", "/render/frames"},
      {"an unknown animation", cube_job(frames, {{"animation", "walk"}}), kCubeRoot, "/scene/animation"},
      {"an animation index the asset does not have", cube_job(frames, {{"animation", 3}}), kCubeRoot,
       "/scene/animation"},
      {"a range with a time of its own", cube_job(frames, {{"time", 1}}), kCubeRoot, "/scene/time"},
      {"a time offset without a range", cube_job(json::object(), {{"time_offset", 1}}), kCubeRoot,
       "/scene/time_offset"},
  };
  for (const Case& c : cases) {
    for (const bool build : {false, true}) {  // checked at submission, and loaded to render
      JobLoadOptions options;
      options.scene.asset_root = c.root;
      options.scene.build = build;
      try {
        load_job(c.job, options);
        ADD_FAILURE() << c.what << " was accepted";
      } catch (const SceneError& e) {
        EXPECT_EQ(e.pointer(), c.pointer) << c.what << ": " << e.what();
      }
    }
  }
}

}  // namespace
}  // namespace tessera
