#include "server/store/work_units.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>

namespace tessera::server {

int unit_count(const RenderSettings& settings, uint64_t unit_pixel_samples) {
  if (unit_pixel_samples == 0) return 1;
  // A render that stops on time or noise, or stops pixels adaptively (each pixel's stop depends on all the samples
  // before it, so sample ranges rendered apart would stop differently than one render of them all), renders whole.
  if (settings.time_limit_s > 0 || settings.noise_target > 0 || settings.adaptive_threshold > 0) return 1;
  if (renders_frames(settings)) return 1;
  // In double: width x height x spp may pass 2^64; the unit count only needs to be about right.
  const double units = std::ceil(static_cast<double>(settings.width) * static_cast<double>(settings.height) *
                                 static_cast<double>(settings.spp) / static_cast<double>(unit_pixel_samples));
  return static_cast<int>(std::clamp<double>(units, 1, static_cast<double>(std::min<uint64_t>(settings.spp, 1 << 16))));
}

bool renders_frames(const RenderSettings& settings) {
  return settings.frames && frame_count(*settings.frames) > 1;
}

int frame_unit_count(const RenderSettings& settings) {
  if (!renders_frames(settings)) return 1;
  const uint64_t chunk = static_cast<uint64_t>(std::max<int64_t>(settings.frames->chunk, 1));
  return static_cast<int>((frame_count(*settings.frames) + chunk - 1) / chunk);
}

std::vector<int64_t> unit_frames(const RenderSettings& settings, int unit) {
  if (!renders_frames(settings) || unit < 0) return {};
  const FrameRange& r = *settings.frames;
  const uint64_t chunk = static_cast<uint64_t>(std::max<int64_t>(r.chunk, 1)), n = frame_count(r);
  std::vector<int64_t> out;
  for (uint64_t i = static_cast<uint64_t>(unit) * chunk; i < n && i < (static_cast<uint64_t>(unit) + 1) * chunk; ++i)
    out.push_back(r.start + static_cast<int64_t>(i) * r.step);
  return out;
}

int job_units(const RenderSettings& settings, uint64_t unit_pixel_samples) {
  return renders_frames(settings) ? frame_unit_count(settings) : unit_count(settings, unit_pixel_samples);
}

uint32_t job_samples_total(const RenderSettings& settings) {
  const uint64_t frames = renders_frames(settings) ? frame_count(*settings.frames) : 1;
  return static_cast<uint32_t>(std::min<uint64_t>(uint64_t{settings.spp} * frames, UINT32_MAX));
}

std::vector<SampleRange> unit_sample_ranges(const std::string& settings_text, uint32_t samples_total, int units) {
  const RenderSettings settings = render_settings_from_text(settings_text);
  if (!renders_frames(settings)) return split_samples(samples_total, units);
  std::vector<SampleRange> out;
  for (int u = 0; u < units; ++u)
    out.push_back({0, static_cast<uint32_t>(settings.spp * unit_frames(settings, u).size())});
  return out;
}

std::vector<SampleRange> split_samples(uint32_t spp, int units) {
  std::vector<SampleRange> out;
  if (units < 1) units = 1;
  const uint32_t n = static_cast<uint32_t>(units), base = spp / n, extra = spp % n;
  uint32_t first = 0;
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t count = base + (i < extra ? 1 : 0);
    out.push_back({first, count});
    first += count;
  }
  return out;
}

}  // namespace tessera::server
