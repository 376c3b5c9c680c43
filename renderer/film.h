// The film: per-pixel sums of linear radiance samples (the measurement equation's estimate for each pixel,
// seed 004, with a box pixel filter), plus what the noise estimate needs.
#pragma once

#include <cstdint>
#include <vector>

#include "renderer/math.h"

namespace tessera {

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
    sum_[3 * i] += radiance.x;
    sum_[3 * i + 1] += radiance.y;
    sum_[3 * i + 2] += radiance.z;
    float l = luminance(radiance);
    sum_lum2_[i] += l * l;
  }
  // Mean radiance of a pixel.
  Rgb pixel(int x, int y) const {
    size_t i = index(x, y);
    float inv = samples_ > 0 ? 1.0f / static_cast<float>(samples_) : 0.0f;
    return Rgb(sum_[3 * i], sum_[3 * i + 1], sum_[3 * i + 2]) * inv;
  }
  // Mean radiance of every pixel, RGB interleaved, row-major from the top-left.
  std::vector<float> resolve() const;
  // Estimated relative standard error of the image mean luminance: sqrt(mean pixel variance of the mean) divided by
  // the mean luminance (over pixels whose mean luminance is above a small floor).
  double relative_error() const;

  // Raw state, for checkpoints.
  const std::vector<float>& sums() const { return sum_; }
  const std::vector<float>& sums_lum2() const { return sum_lum2_; }
  std::vector<float>& sums() { return sum_; }
  std::vector<float>& sums_lum2() { return sum_lum2_; }

 private:
  size_t index(int x, int y) const { return static_cast<size_t>(y) * static_cast<size_t>(width_) + static_cast<size_t>(x); }
  int width_ = 0, height_ = 0;
  uint32_t samples_ = 0;
  std::vector<float> sum_;
  std::vector<float> sum_lum2_;
};

}  // namespace tessera
