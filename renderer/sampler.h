// Deterministic random numbers: every value depends only on (seed, pixel, sample index, dimension), so an image is
// the same whatever the thread count, tile order or pass boundaries, and a render resumed at sample N continues
// exactly where an uninterrupted one would.
#pragma once

#include <cstdint>

#include "renderer/math.h"

namespace tessera {

// 64-bit finaliser of SplitMix64 / MurmurHash3: a bijective mix with full avalanche.
constexpr uint64_t mix64(uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}

class PixelSampler {
 public:
  PixelSampler(uint64_t seed, uint32_t pixel_index, uint64_t sample_index)
      : key_(mix64(mix64(seed ^ 0x9e3779b97f4a7c15ULL) + pixel_index) ^ mix64(sample_index + 0x632be59bd9b4e019ULL)) {}

  // Next uniform number in [0, 1).
  float get1d() { return to_unit(mix64(key_ + 0x9e3779b97f4a7c15ULL * ++dimension_)); }
  Vec2 get2d() {
    float a = get1d();
    return {a, get1d()};
  }
  uint32_t dimension() const { return dimension_; }

 private:
  static float to_unit(uint64_t bits) {
    // 24 high bits give every float in [0, 1) on a 2^-24 grid; never returns 1.
    return static_cast<float>(bits >> 40) * 0x1p-24f;
  }
  uint64_t key_;
  uint32_t dimension_ = 0;
};

}  // namespace tessera
