// Frame ranges (renderer/frames.h) and their settings (render.frames, render.fps in render_settings.h): the frames a
// range holds and their times, the numbered file names and their padding, and every bad range refused naming its
// field.
#include "renderer/frames.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "renderer/render_settings.h"
#include "renderer/scene_error.h"

namespace tessera {
namespace {

using nlohmann::json;

TEST(Frames, ARangeHoldsEveryStepthFrameUpToItsEnd) {
  EXPECT_EQ(frame_numbers({1, 48, 1, 1}).size(), 48u);
  EXPECT_EQ(frame_numbers({1, 10, 4, 1}), (std::vector<int64_t>{1, 5, 9}));
  EXPECT_EQ(frame_numbers({-3, 3, 3, 1}), (std::vector<int64_t>{-3, 0, 3}));
  EXPECT_EQ(frame_numbers({7, 7, 5, 1}), (std::vector<int64_t>{7}));
  EXPECT_EQ(frame_count({-kMaxFrameNumber, kMaxFrameNumber, 1, 1}), 2'000'000'001u);
  // Frame f is at f / fps + offset, whatever range holds it.
  EXPECT_EQ(frame_time(12, 24, 0), 0.5);
  EXPECT_EQ(frame_time(-24, 24, 0.25), -0.75);
  EXPECT_EQ(frame_time(1001, 24000.0 / 1001, 0), 1001 / (24000.0 / 1001));
}

// At least 4 digits; as many characters as the range's widest frame (sign included) where that is more, so that every
// name of a sequence has one length; zeros after the sign, as printf's %0*d writes them.
TEST(Frames, PaddingIsChosenFromTheRange) {
  EXPECT_EQ(frame_padding({1, 48, 1, 1}), 4);
  EXPECT_EQ(frame_padding({1, 9999, 1, 1}), 4);
  EXPECT_EQ(frame_padding({1, 10000, 1, 1}), 5);
  EXPECT_EQ(frame_padding({1, 10000, 2, 1}), 4);  // its last frame is 9999
  EXPECT_EQ(frame_padding({0, 123456, 1, 1}), 6);
  EXPECT_EQ(frame_padding({-1, 1, 1, 1}), 4);
  EXPECT_EQ(frame_padding({-12345, 0, 1, 1}), 6);
  EXPECT_EQ(frame_padding({-kMaxFrameNumber, kMaxFrameNumber, 1, 1}), 11);
  EXPECT_EQ(frame_number_text(1, 4), "0001");
  EXPECT_EQ(frame_number_text(42, 4), "0042");
  EXPECT_EQ(frame_number_text(12345, 5), "12345");
  EXPECT_EQ(frame_number_text(-1, 4), "-001");
  EXPECT_EQ(frame_number_text(-5, 6), "-00005");
  EXPECT_EQ(frame_number_text(3, 6), "000003");
  EXPECT_EQ(frame_path("out/cube.png", 7, 4), "out/cube.0007.png");
  EXPECT_EQ(frame_path("render.v2.exr", 120, 4), "render.v2.0120.exr");
  EXPECT_EQ(frame_path("film", -2, 4), "film.-002");
}

TEST(Frames, AFramesSceneIsTheStillAtItsTime) {
  const json scene = {{"gltf", "a.glb"}, {"animation", "walk"}, {"time_offset", 0.5}};
  const json frame = frame_scene(scene, 12, 24);
  EXPECT_EQ(frame, (json{{"gltf", "a.glb"}, {"animation", "walk"}, {"time", 1.0}}));
  EXPECT_EQ(frame_scene({{"gltf", "a.glb"}}, 6, 24)["time"], 0.25);
}

RenderSettings read(const json& render, RenderLimits limits = {}) {
  return render_settings_from_json(render, "/render", limits);
}

TEST(FrameSettings, ARangeAndFpsReadAndWriteBack) {
  const RenderSettings s = read({{"frames", {{"start", -2}, {"end", 40}, {"step", 3}}}, {"fps", 23.976}});
  ASSERT_TRUE(s.frames);
  EXPECT_EQ(*s.frames, (FrameRange{-2, 40, 3, 1}));
  EXPECT_EQ(s.fps, 23.976);
  const json out = render_settings_to_json(s);
  EXPECT_EQ(out["frames"], (json{{"start", -2}, {"end", 40}, {"step", 3}, {"chunk", 1}}));
  EXPECT_EQ(out["fps"], 23.976);
  EXPECT_EQ(render_settings_from_text(render_settings_text(s)), s);
  // A still writes neither, so that records of stills keep their text.
  const json still = render_settings_to_json(read(json::object()));
  EXPECT_FALSE(still.contains("frames"));
  EXPECT_FALSE(still.contains("fps"));
  EXPECT_FALSE(read(json::object()).frames);
  // A stored range above a server's limit (it took the job with a higher --max-frames) still reads.
  RenderLimits generous;
  generous.max_frames = 1'000'000;
  const RenderSettings big = read({{"frames", {{"start", 1}, {"end", 20000}}}}, generous);
  EXPECT_EQ(render_settings_from_text(render_settings_text(big)), big);
}

TEST(FrameSettings, BadRangesAreRefusedNamingTheField) {
  RenderLimits ten;
  ten.max_frames = 10;
  struct Case {
    json render;
    const char* pointer;
  };
  const Case cases[] = {
      {{{"frames", {{"start", 5}, {"end", 4}}}}, "/render/frames/end"},
      {{{"frames", {{"start", 1}, {"end", 4}, {"step", 0}}}}, "/render/frames/step"},
      {{{"frames", {{"start", 1}, {"end", 4}, {"step", -1}}}}, "/render/frames/step"},
      {{{"frames", {{"start", 1}, {"end", 4}, {"chunk", 0}}}}, "/render/frames/chunk"},
      {{{"frames", {{"start", 1}, {"end", 4}, {"step", 1.5}}}}, "/render/frames/step"},
      {{{"frames", {{"end", 4}}}}, "/render/frames/start"},
      {{{"frames", {{"start", 1}}}}, "/render/frames/end"},
      {{{"frames", {{"start", 1}, {"end", 11}}}}, "/render/frames"},  // 11 frames, above the limit
      {{{"frames", {{"start", 0}, {"end", 2'000'000'000}}}}, "/render/frames/end"},
      {{{"frames", "1-48"}}, "/render/frames"},
      {{{"fps", 0}}, "/render/fps"},
      {{{"fps", -24}}, "/render/fps"},
      {{{"fps", std::numeric_limits<double>::infinity()}}, "/render/fps"},
      {{{"fps", std::nan("")}}, "/render/fps"},
      {{{"fps", "24"}}, "/render/fps"},
  };
  for (const Case& c : cases) {
    try {
      read(c.render, ten);
      ADD_FAILURE() << c.render.dump() << " was accepted";
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), c.pointer) << c.render.dump() << ": " << e.what();
    }
  }
  // The limit itself is a range's to reach.
  EXPECT_EQ(frame_count(*read({{"frames", {{"start", 1}, {"end", 10}}}}, ten).frames), 10u);
  try {
    read({{"frames", {{"start", 1}, {"end", 11}}}}, ten);
  } catch (const SceneError& e) {
    EXPECT_STREQ(e.what(), "the range holds 11 frames, more than the 10 a job may have");
  }
}

}  // namespace
}  // namespace tessera
