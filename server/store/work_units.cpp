#include "server/store/work_units.h"

#include <algorithm>
#include <cmath>

namespace tessera::server {

int unit_count(const RenderSettings& settings, uint64_t unit_pixel_samples) {
  if (unit_pixel_samples == 0) return 1;
  // A render that stops on time or noise, or stops pixels adaptively (each pixel's stop depends on all the samples
  // before it, so sample ranges rendered apart would stop differently than one render of them all), renders whole.
  if (settings.time_limit_s > 0 || settings.noise_target > 0 || settings.adaptive_threshold > 0) return 1;
  // A frame range is rendered frame by frame in one run (server/jobs/render_work.h: renders_frames).
  if (settings.frames && frame_count(*settings.frames) > 1) return 1;
  // In double: width x height x spp may pass 2^64; the unit count only needs to be about right.
  const double units = std::ceil(static_cast<double>(settings.width) * static_cast<double>(settings.height) *
                                 static_cast<double>(settings.spp) / static_cast<double>(unit_pixel_samples));
  return static_cast<int>(std::clamp<double>(units, 1, static_cast<double>(std::min<uint64_t>(settings.spp, 1 << 16))));
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
