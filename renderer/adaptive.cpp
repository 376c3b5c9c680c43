#include "renderer/adaptive.h"

#include <algorithm>
#include <cmath>

namespace tessera {

AdaptiveSampling::AdaptiveSampling(const RenderSettings& settings) : spp_(settings.spp) {
  if (!(settings.adaptive_threshold > 0) || settings.spp == 0) return;
  const double share = static_cast<double>(settings.spp) / static_cast<double>(settings.budget());
  threshold_ = settings.adaptive_threshold / std::sqrt(share);
  const uint32_t job_min = std::clamp<uint32_t>(settings.min_spp, 1, settings.budget());
  min_spp_ = std::clamp<uint32_t>(static_cast<uint32_t>(std::ceil(job_min * share - 1e-9)), 1, settings.spp);
}

uint32_t AdaptiveSampling::next_decision_point(uint32_t n) const {
  if (!enabled()) return spp_;
  const uint64_t next = (static_cast<uint64_t>(n) / min_spp_ + 1) * min_spp_;
  return static_cast<uint32_t>(std::min<uint64_t>(next, spp_));
}

double AdaptiveSampling::pixel_error(const Film& film, size_t i) {
  const uint32_t count = film.pixel_sample_counts()[i];
  if (count < 2) return INFINITY;
  const double n = count;
  const FixedSum* sum = &film.sums()[3 * i];
  // Luminance with the weights of Film::add_sample's squared luminance (ITU-R BT.709).
  const double mean = (0.2126 * static_cast<double>(sum[0]) + 0.7152 * static_cast<double>(sum[1]) +
                       0.0722 * static_cast<double>(sum[2])) /
                      (kFixedScale * n);
  const double var = std::max(0.0, (film.sums_lum2()[i] / n - mean * mean) * n / (n - 1));
  const double standard_error = std::sqrt(var / n);
  const double scale = mean >= 1 ? mean : std::sqrt(std::max(mean, 1e-4));
  return standard_error / scale;
}

size_t AdaptiveSampling::active_pixels(const Film& film, const PixelRegion& region, PixelMask& active) const {
  const uint32_t n = film.samples();
  const std::vector<uint32_t>& counts = film.pixel_sample_counts();
  const size_t width = static_cast<size_t>(film.width());
  active.assign(film.pixel_count(), 0);
  size_t total = 0;
  const int x0 = region.x, y0 = region.y, x1 = region.x + region.width, y1 = region.y + region.height;
  if (!is_decision_point(n)) {
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) {
        const size_t i = static_cast<size_t>(y) * width + static_cast<size_t>(x);
        active[i] = counts[i] == n ? 1 : 0;
        total += active[i];
      }
    return total;
  }
  // Which pixels of the region are above the threshold, then each still-sampling pixel looks at its 3x3
  // neighbourhood (within the region).
  PixelMask above(film.pixel_count(), 0);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) {
      const size_t i = static_cast<size_t>(y) * width + static_cast<size_t>(x);
      above[i] = pixel_error(film, i) > threshold_ ? 1 : 0;
    }
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) {
      const size_t i = static_cast<size_t>(y) * width + static_cast<size_t>(x);
      if (counts[i] != n) continue;
      uint8_t any = 0;
      for (int ny = std::max(y - 1, y0); ny <= std::min(y + 1, y1 - 1) && !any; ++ny)
        for (int nx = std::max(x - 1, x0); nx <= std::min(x + 1, x1 - 1); ++nx)
          any |= above[static_cast<size_t>(ny) * width + static_cast<size_t>(nx)];
      active[i] = any;
      total += any;
    }
  return total;
}

}  // namespace tessera
