#include "renderer/film.h"

#include <cmath>
#include <cstring>
#include <stdexcept>

namespace tessera {

Film::Film(int width, int height)
    : width_(width), height_(height), sum_(3 * pixel_count(), 0), sum_lum2_(pixel_count(), 0.0f) {}

std::vector<float> Film::resolve() const {
  std::vector<float> out(sum_.size());
  double inv = samples_ > 0 ? 1.0 / (kFixedScale * samples_) : 0.0;
  for (size_t i = 0; i < sum_.size(); ++i) out[i] = static_cast<float>(static_cast<double>(sum_[i]) * inv);
  return out;
}

size_t Film::state_size(int width, int height) {
  return static_cast<size_t>(width) * static_cast<size_t>(height) * (3 * sizeof(FixedSum) + sizeof(float));
}

void Film::append_state(std::string& out) const {
  out.append(reinterpret_cast<const char*>(sum_.data()), sum_.size() * sizeof(FixedSum));
  out.append(reinterpret_cast<const char*>(sum_lum2_.data()), sum_lum2_.size() * sizeof(float));
}

bool Film::read_state(std::string_view bytes) {
  if (bytes.size() != state_size(width_, height_)) return false;
  const size_t sums_bytes = sum_.size() * sizeof(FixedSum);
  std::memcpy(sum_.data(), bytes.data(), sums_bytes);
  std::memcpy(sum_lum2_.data(), bytes.data() + sums_bytes, sum_lum2_.size() * sizeof(float));
  return true;
}

void Film::merge(const Film& other) {
  if (other.width_ != width_ || other.height_ != height_) throw std::invalid_argument("films of different sizes");
  for (size_t i = 0; i < sum_.size(); ++i) sum_[i] += other.sum_[i];
  for (size_t i = 0; i < sum_lum2_.size(); ++i) sum_lum2_[i] += other.sum_lum2_[i];
  samples_ += other.samples_;
}

double Film::relative_error() const {
  if (samples_ < 2) return INFINITY;
  const double n = samples_;
  double var_sum = 0, lum_sum = 0;
  size_t count = 0;
  for (size_t i = 0; i < pixel_count(); ++i) {
    double mean = (0.2126 * static_cast<double>(sum_[3 * i]) + 0.7152 * static_cast<double>(sum_[3 * i + 1]) +
                   0.0722 * static_cast<double>(sum_[3 * i + 2])) /
                  (kFixedScale * n);
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
