#include "renderer/frames.h"

#include <algorithm>
#include <cinttypes>
#include <cstdio>

namespace tessera {

uint64_t frame_count(const FrameRange& range) {
  if (range.end < range.start || range.step < 1) return 0;
  return static_cast<uint64_t>(range.end - range.start) / static_cast<uint64_t>(range.step) + 1;
}

std::vector<int64_t> frame_numbers(const FrameRange& range) {
  std::vector<int64_t> frames;
  const uint64_t n = frame_count(range);
  frames.reserve(n);
  for (uint64_t i = 0; i < n; ++i) frames.push_back(range.start + static_cast<int64_t>(i) * range.step);
  return frames;
}

std::vector<double> shutter_step_times(const Shutter& shutter, double fps) {
  std::vector<double> times;
  const int n = std::max(shutter.steps, 2);
  for (int i = 0; i < n; ++i) times.push_back((shutter.open + (shutter.close - shutter.open) * i / (n - 1)) / fps);
  return times;
}

double frame_time(int64_t frame, double fps, double time_offset) {
  return static_cast<double>(frame) / fps + time_offset;
}

int frame_padding(const FrameRange& range) {
  const uint64_t n = frame_count(range);
  const int64_t last = n ? range.start + static_cast<int64_t>(n - 1) * range.step : range.start;
  auto chars = [](int64_t f) { return static_cast<int>(std::to_string(f).size()); };
  return std::max({4, chars(range.start), chars(last)});
}

std::string frame_number_text(int64_t frame, int width) {
  char text[32];
  std::snprintf(text, sizeof text, "%0*" PRId64, std::clamp(width, 1, 24), frame);
  return text;
}

std::filesystem::path frame_path(const std::filesystem::path& path, int64_t frame, int width) {
  std::filesystem::path out = path;
  out.replace_filename(path.stem().string() + "." + frame_number_text(frame, width) + path.extension().string());
  return out;
}

nlohmann::json frame_scene(const nlohmann::json& scene, int64_t frame, double fps) {
  if (!scene.is_object()) return scene;  // the scene loader names what is wrong with it
  nlohmann::json out = scene;
  double offset = 0;
  if (auto it = out.find("time_offset"); it != out.end()) {
    if (it->is_number()) offset = it->get<double>();
    out.erase(it);
  }
  out["time"] = frame_time(frame, fps, offset);
  return out;
}

}  // namespace tessera
