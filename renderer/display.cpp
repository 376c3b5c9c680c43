#include "renderer/display.h"

#include <cmath>

#include "renderer/math.h"

namespace tessera {

namespace {

// Narkowicz's fit of the ACES reference rendering transform with its output transform, applied per channel.
float aces_fit(float x) {
  const float a = 2.51f, b = 0.03f, c = 2.43f, d = 0.59f, e = 0.14f;
  return clamp((x * (a * x + b)) / (x * (c * x + d) + e), 0.0f, 1.0f);
}

float srgb_encode(float linear) {
  if (!(linear > 0)) return 0;
  if (linear >= 1) return 1;
  return linear <= 0.0031308f ? 12.92f * linear : 1.055f * std::pow(linear, 1.0f / 2.4f) - 0.055f;
}

}  // namespace

std::vector<uint8_t> to_display(const std::vector<float>& rgb, int width, int height, const DisplaySettings& display) {
  const float scale = std::exp2(display.exposure_ev);
  std::vector<uint8_t> out(static_cast<size_t>(width) * static_cast<size_t>(height) * 3);
  for (size_t i = 0; i < out.size(); ++i) {
    float v = rgb[i] * scale;
    if (!std::isfinite(v)) v = v > 0 ? 1.0f : 0.0f;
    if (display.tonemap == ToneMap::kAces) v = aces_fit(v);
    out[i] = static_cast<uint8_t>(std::lround(srgb_encode(v) * 255.0f));
  }
  return out;
}

}  // namespace tessera
