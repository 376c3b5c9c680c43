// How linear radiance is shown on an 8-bit display: an exposure, a tone curve, the sRGB transfer function.
#pragma once

#include <cstdint>
#include <vector>

namespace tessera {

enum class ToneMap { kClamp, kAces };

struct DisplaySettings {
  float exposure_ev = 0;  // scale by 2^exposure_ev before the tone curve
  ToneMap tonemap = ToneMap::kClamp;
  bool operator==(const DisplaySettings&) const = default;
};

// Linear radiance (RGB float, row-major) to 8-bit sRGB (IEC 61966-2-1), applying exposure and the tone curve.
std::vector<uint8_t> to_display(const std::vector<float>& rgb, int width, int height, const DisplaySettings& display);

}  // namespace tessera
