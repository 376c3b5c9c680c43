// The film: per-pixel sums of linear radiance samples (each pixel's estimate of the measurement equation, Dutré, Bala
// & Bekaert, Advanced Global Illumination, 2nd ed., §2.8, with a box pixel filter), plus what the noise estimate needs.
//
// Radiance sums are kept in 128-bit fixed point (units of 2^-40). Integer addition is associative, so a pixel's sum
// does not depend on the order its samples were added in: films of disjoint sample ranges merge into exactly the
// image of one render of all samples, whatever the threads, tiles, passes or resumes. Samples are clamped to
// [0, 2^80] (far beyond any physical radiance) so sums cannot overflow.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "renderer/math.h"

namespace tessera {

using FixedSum = __int128;
inline constexpr double kFixedScale = 0x1p40;

class Film {
 public:
  Film() = default;
  Film(int width, int height);

  int width() const { return width_; }
  int height() const { return height_; }
  size_t pixel_count() const { return static_cast<size_t>(width_) * static_cast<size_t>(height_); }
  // Samples every pixel has received (all pixels advance together, pass by pass).
  uint32_t samples() const { return samples_; }
  void set_samples(uint32_t n) { samples_ = n; }

  void add_sample(int x, int y, const Rgb& radiance) {
    size_t i = index(x, y);
    sum_[3 * i] += to_fixed(radiance.x);
    sum_[3 * i + 1] += to_fixed(radiance.y);
    sum_[3 * i + 2] += to_fixed(radiance.z);
    float l = luminance(radiance);
    sum_lum2_[i] += l * l;
  }
  // Adds `value` to the radiance sums of pixel (x, y) while other threads may add to the same pixel: a light path's
  // contribution lands wherever it projects (Veach 1997, 10.3.4), not in a pixel a thread owns. Each 128-bit sum is
  // added as two 64-bit atomic additions, the carry of the low word into the high one: integer additions in any
  // order and interleaving end in the same bits, so a film of splats is the same whatever the threads. Splats do not
  // count as samples and leave the squared-luminance sums (the noise estimate's) alone.
  void splat(int x, int y, const Rgb& value) {
    size_t i = index(x, y);
    for (int c = 0; c < 3; ++c) atomic_add(sum_[3 * i + static_cast<size_t>(c)], to_fixed(value[c]));
  }
  // add_sample on a film that other threads splat onto at the same time: the radiance sums added as splat() adds
  // them; the squared luminance as add_sample does (only the calling thread adds samples to this pixel).
  void add_sample_shared(int x, int y, const Rgb& radiance) {
    splat(x, y, radiance);
    float l = luminance(radiance);
    sum_lum2_[index(x, y)] += l * l;
  }
  // Mean radiance of a pixel.
  Rgb pixel(int x, int y) const {
    size_t i = index(x, y);
    double inv = samples_ > 0 ? 1.0 / (kFixedScale * samples_) : 0.0;
    return Rgb(static_cast<float>(static_cast<double>(sum_[3 * i]) * inv),
               static_cast<float>(static_cast<double>(sum_[3 * i + 1]) * inv),
               static_cast<float>(static_cast<double>(sum_[3 * i + 2]) * inv));
  }
  // Adds the samples of `other` (same size, a disjoint sample range): exact for the radiance sums.
  void merge(const Film& other);
  // Mean radiance of every pixel, RGB interleaved, row-major from the top-left.
  std::vector<float> resolve() const;
  // Estimated relative standard error of the image mean luminance: sqrt(mean pixel variance of the mean) divided by
  // the mean luminance (over pixels whose mean luminance is above a small floor).
  double relative_error() const;

  // The film's state as bytes, the one layout of checkpoints and partial films: 3 × 128-bit fixed-point sums per
  // pixel (R, G, B, units of 2^-40), row-major from the top left, then one f32 sum of squared luminance per pixel;
  // in the machine's byte order (little-endian on the machines we run on). The sample count is not part of it.
  static size_t state_size(int width, int height);
  void append_state(std::string& out) const;
  // Reads state_size(width(), height()) bytes of append_state(); false, and the film unchanged, for any other size.
  bool read_state(std::string_view bytes);

  // Raw state: 3 fixed-point sums per pixel (RGB), and per-pixel sums of squared luminance (float, only for the noise
  // estimate).
  const std::vector<FixedSum>& sums() const { return sum_; }
  const std::vector<float>& sums_lum2() const { return sum_lum2_; }
  std::vector<FixedSum>& sums() { return sum_; }
  std::vector<float>& sums_lum2() { return sum_lum2_; }

  static FixedSum to_fixed(float v) {
    double d = static_cast<double>(v);
    if (!(d > 0)) return 0;
    // Below 2^23 the scaled value fits in 63 bits: one hardware conversion, the same truncation as the 128-bit one
    // (which is a library call, and was a measurable share of the render loop).
    if (d < 0x1p23) return static_cast<int64_t>(d * kFixedScale);
    if (d > 0x1p80) d = 0x1p80;
    return static_cast<FixedSum>(d * kFixedScale);
  }

 private:
  static void atomic_add(FixedSum& sum, FixedSum value) {
    // Little-endian: the low word first. Sums are non-negative and below 2^127, the words' wrap-around is exact.
    static_assert(sizeof(FixedSum) == 2 * sizeof(uint64_t));
    uint64_t* words = reinterpret_cast<uint64_t*>(&sum);
    const uint64_t lo = static_cast<uint64_t>(value), hi = static_cast<uint64_t>(value >> 64);
    const uint64_t before = __atomic_fetch_add(&words[0], lo, __ATOMIC_RELAXED);
    const uint64_t carry = before + lo < before ? 1 : 0;
    if (hi + carry != 0) __atomic_fetch_add(&words[1], hi + carry, __ATOMIC_RELAXED);
  }
  size_t index(int x, int y) const {
    return static_cast<size_t>(y) * static_cast<size_t>(width_) + static_cast<size_t>(x);
  }
  int width_ = 0, height_ = 0;
  uint32_t samples_ = 0;
  std::vector<FixedSum> sum_;
  std::vector<float> sum_lum2_;
};

}  // namespace tessera
