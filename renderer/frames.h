// Frame ranges of an animation (render.frames, render.fps, scene.time_offset): which frames a range holds, the time
// of each, and the numbered file name of each. One place for these rules, so that the command line and the daemon
// number, time and name a job's frames alike.
//
// Frame f is at f / fps + time_offset seconds, whatever range it is asked in, and is rendered with the job's seed:
// a frame is exactly the still of the asset at its time (scene.time).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace tessera {

// render.frames: frames start, start + step, ... up to end (inclusive); chunk groups consecutive frames of the range
// into one work unit (a range rendered on one node renders them all the same).
struct FrameRange {
  int64_t start = 0;
  int64_t end = 0;
  int64_t step = 1;
  int64_t chunk = 1;

  bool operator==(const FrameRange&) const = default;
};

// render.shutter: a box shutter open from `open` to `close` frames relative to the frame (a still's: around scene.time,
// in frames at render.fps), over which moving geometry and cameras blur. Each object's motion is sampled at `steps`
// times spread evenly over the interval and interpolated linearly between them (Embree's time steps).
struct Shutter {
  double open = -0.25;
  double close = 0.25;
  int steps = 2;

  bool operator==(const Shutter&) const = default;
};
constexpr double kMaxShutterFrames = 10;  // |open| and |close| at most this many frames from the frame
constexpr int kMaxShutterSteps = 129;     // Embree 3's most time steps per geometry (RTC_MAX_TIME_STEP_COUNT)

// The shutter's times in seconds relative to the frame's: its `steps` sample times, open to close, at `fps`.
std::vector<double> shutter_step_times(const Shutter& shutter, double fps);

constexpr double kDefaultFps = 24;  // render.fps when the job does not say (the contract's default)
// Frame numbers are within +-kMaxFrameNumber (the contract's bound): every number fits 10 digits and a sign.
constexpr int64_t kMaxFrameNumber = 1'000'000'000;

// How many frames the range holds (start <= end, step >= 1).
uint64_t frame_count(const FrameRange& range);
// Its frame numbers in order: start, start + step, ... <= end.
std::vector<int64_t> frame_numbers(const FrameRange& range);
// The time in seconds of frame `frame`: frame / fps + time_offset.
double frame_time(int64_t frame, double fps, double time_offset);

// The number of characters every frame number of the range is written with: that of its widest frame, sign
// included, and at least 4 (name.0001.exr), so that the names of one sequence have one length and read as the
// printf pattern name.%0<width>d.exr (as Nuke, Blender and ffmpeg read sequences).
int frame_padding(const FrameRange& range);
// Frame `frame` written with `width` characters as printf's %0*d writes it: zeros after the sign (-001, 0042).
std::string frame_number_text(int64_t frame, int width);
// The file of frame `frame` for the output `path`: its number before the extension (out.png -> out.0001.png; a
// name without an extension gets the number at its end: out -> out.0001).
std::filesystem::path frame_path(const std::filesystem::path& path, int64_t frame, int width);

// The "scene" object of frame `frame` of a scene whose frames are at `fps`: scene.time set to the frame's time
// (scene.time_offset added in, and left out), the still of that frame.
nlohmann::json frame_scene(const nlohmann::json& scene, int64_t frame, double fps);

}  // namespace tessera
