#include "renderer/film.h"

#include <cmath>

namespace tessera {

Film::Film(int width, int height)
    : width_(width), height_(height), sum_(3 * pixel_count(), 0.0f), sum_lum2_(pixel_count(), 0.0f) {}

std::vector<float> Film::resolve() const {
  std::vector<float> out(sum_.size());
  float inv = samples_ > 0 ? 1.0f / static_cast<float>(samples_) : 0.0f;
  for (size_t i = 0; i < sum_.size(); ++i) out[i] = sum_[i] * inv;
  return out;
}

double Film::relative_error() const {
  if (samples_ < 2) return INFINITY;
  const double n = samples_;
  double var_sum = 0, lum_sum = 0;
  size_t count = 0;
  for (size_t i = 0; i < pixel_count(); ++i) {
    double mean = (0.2126 * sum_[3 * i] + 0.7152 * sum_[3 * i + 1] + 0.0722 * sum_[3 * i + 2]) / n;
    double var = (sum_lum2_[i] / n - mean * mean) * n / (n - 1);  // unbiased sample variance
    if (var < 0) var = 0;
    var_sum += var / n;  // variance of the pixel mean
    lum_sum += mean;
    ++count;
  }
  if (count == 0 || lum_sum <= 0) return INFINITY;
  double mean_lum = lum_sum / count;
  double rms_error = std::sqrt(var_sum / count);
  return rms_error / mean_lum;
}

}  // namespace tessera
