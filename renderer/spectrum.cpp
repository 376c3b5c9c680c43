// Wavelength sampling for dispersion (spectrum.h).
#include "renderer/spectrum.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace tessera::spectrum {

namespace {

// A lobe of the fit: exp(-t^2 / 2) with t = (lambda - mean) times the inverse width on its side of the mean.
float lobe(float lambda_nm, float mean, float inv_width_below, float inv_width_above) {
  const float t = (lambda_nm - mean) * (lambda_nm < mean ? inv_width_below : inv_width_above);
  return std::exp(-0.5f * t * t);
}

constexpr int kBins = static_cast<int>(kMaxNm - kMinNm);  // 1 nm each

// The tabulated weights (at each bin's centre), each channel scaled to sum to 1 over the bins (1 nm each: to
// integrate to 1), the density p = their mean, and its cumulative distribution.
struct Table {
  std::array<Rgb, kBins> weight;
  std::array<float, kBins> pdf;
  std::array<float, kBins + 1> cdf;

  Table() {
    Vec3 sum(0);
    for (int i = 0; i < kBins; ++i) {
      const Vec3 xyz = cie_xyz(kMinNm + static_cast<float>(i) + 0.5f);
      const Rgb c = xyz_to_linear_srgb(xyz.x, xyz.y, xyz.z);
      weight[static_cast<size_t>(i)] = Rgb(std::max(c.x, 0.0f), std::max(c.y, 0.0f), std::max(c.z, 0.0f));
      sum += weight[static_cast<size_t>(i)];
    }
    cdf[0] = 0;
    for (int i = 0; i < kBins; ++i) {
      Rgb& w = weight[static_cast<size_t>(i)];
      w = Rgb(w.x / sum.x, w.y / sum.y, w.z / sum.z);
      pdf[static_cast<size_t>(i)] = (w.x + w.y + w.z) / 3;
      cdf[static_cast<size_t>(i) + 1] = cdf[static_cast<size_t>(i)] + pdf[static_cast<size_t>(i)];
    }
  }
};

const Table& table() {
  static const Table t;
  return t;
}

int bin_of(float lambda_nm) {
  return std::clamp(static_cast<int>(std::floor(lambda_nm - kMinNm)), 0, kBins - 1);
}

}  // namespace

Vec3 cie_xyz(float lambda_nm) {
  const float x = 1.056f * lobe(lambda_nm, 599.8f, 0.0264f, 0.0323f) +
                  0.362f * lobe(lambda_nm, 442.0f, 0.0624f, 0.0374f) -
                  0.065f * lobe(lambda_nm, 501.1f, 0.0490f, 0.0382f);
  const float y =
      0.821f * lobe(lambda_nm, 568.8f, 0.0213f, 0.0247f) + 0.286f * lobe(lambda_nm, 530.9f, 0.0613f, 0.0322f);
  const float z =
      1.217f * lobe(lambda_nm, 437.0f, 0.0845f, 0.0278f) + 0.681f * lobe(lambda_nm, 459.0f, 0.0385f, 0.0725f);
  return {x, y, z};
}

Rgb xyz_to_linear_srgb(double x, double y, double z) {
  return Rgb(static_cast<float>(3.2404542 * x - 1.5371385 * y - 0.4985314 * z),
             static_cast<float>(-0.9692660 * x + 1.8760108 * y + 0.0415560 * z),
             static_cast<float>(0.0556434 * x - 0.2040259 * y + 1.0572252 * z));
}

WavelengthSample sample_wavelength(float u) {
  const Table& t = table();
  const float target = std::clamp(u, 0.0f, 1.0f) * t.cdf[kBins];
  // The first bin whose cumulative distribution passes the target; bins of zero density are never chosen.
  int i = static_cast<int>(std::upper_bound(t.cdf.begin() + 1, t.cdf.end(), target) - (t.cdf.begin() + 1));
  i = std::min(i, kBins - 1);
  while (i > 0 && t.pdf[static_cast<size_t>(i)] <= 0) --i;
  const float p = t.pdf[static_cast<size_t>(i)];
  const float within = p > 0 ? std::clamp((target - t.cdf[static_cast<size_t>(i)]) / p, 0.0f, 0.999999f) : 0.5f;
  WavelengthSample s;
  s.lambda_nm = kMinNm + static_cast<float>(i) + within;
  s.weight = t.weight[static_cast<size_t>(i)] / p;
  return s;
}

Rgb channel_weight(float lambda_nm) {
  if (!(lambda_nm >= kMinNm && lambda_nm < kMaxNm)) return Rgb(0);
  return table().weight[static_cast<size_t>(bin_of(lambda_nm))];
}

float wavelength_pdf(float lambda_nm) {
  if (!(lambda_nm >= kMinNm && lambda_nm < kMaxNm)) return 0;
  return table().pdf[static_cast<size_t>(bin_of(lambda_nm))];
}

float dispersive_ior(float ior, float dispersion, float lambda_nm) {
  if (dispersion <= 0) return ior;
  return std::max(ior + (ior - 1) * dispersion / 20 * (523655.0f / (lambda_nm * lambda_nm) - 1.5168f), 1.0f);
}

}  // namespace tessera::spectrum
