#include "renderer/denoise.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "renderer/thread_pool.h"

namespace tessera {

namespace {

// The least albedo the beauty is divided by: a black surface's illumination stays finite (the division is undone
// exactly when the denoised illumination is multiplied back). Above it the illumination of two surfaces under the
// same light is the same whatever their albedos.
constexpr float kAlbedoFloor = 0.01f;
// The regression's unknowns: the intercept (the estimate at p), then the slopes of the normal (3) and depth.
constexpr int kDims = 5;
// Rows a task computes: fixed, so that the image is cut the same whatever the threads.
constexpr int kBandRows = 8;
// A neighbour whose weight is below this is left out of the fit (exp(-7)).
constexpr float kMinWeight = 9.1e-4f;
// The ridge term, relative to the sum of the weights, added to the slopes' diagonal: it keeps the system
// well-posed where a feature is constant over the window (a flat wall facing the camera).
constexpr double kRidge = 1e-3;

const ImageLayer& layer_named(const Image& image, const std::string& name, size_t channels) {
  for (const ImageLayer& l : image.layers)
    if (l.name == name && l.channels.size() == channels) return l;
  throw std::invalid_argument("the denoiser needs the pass \"" + name + "\"");
}

// What the denoiser reads per pixel, planar.
struct Inputs {
  int width = 0, height = 0;
  std::array<std::vector<float>, 3> y;         // the illumination
  std::array<std::vector<float>, 3> v;         // its variance
  std::vector<std::array<float, 4>> features;  // normal, depth over the image's largest finite depth
};

// Solves A x = b for a symmetric positive definite A (kDims x kDims, upper triangle given) by its Cholesky
// factorisation (Golub and Van Loan, Matrix Computations, 4th ed., 2013, §4.2.5) for three right-hand sides, and
// returns x[0] of each; false when A is not numerically positive definite.
bool solve_intercepts(const double (&a)[kDims][kDims], const double (&b)[3][kDims], double (&x0)[3]) {
  double l[kDims][kDims] = {};
  for (int j = 0; j < kDims; ++j) {
    double d = a[j][j];
    for (int k = 0; k < j; ++k) d -= l[j][k] * l[j][k];
    if (!(d > 1e-12 * a[0][0])) return false;
    l[j][j] = std::sqrt(d);
    for (int i = j + 1; i < kDims; ++i) {
      double s = a[j][i];
      for (int k = 0; k < j; ++k) s -= l[i][k] * l[j][k];
      l[i][j] = s / l[j][j];
    }
  }
  for (int c = 0; c < 3; ++c) {
    double z[kDims], x[kDims];
    for (int i = 0; i < kDims; ++i) {
      double s = b[c][i];
      for (int k = 0; k < i; ++k) s -= l[i][k] * z[k];
      z[i] = s / l[i][i];
    }
    for (int i = kDims - 1; i >= 0; --i) {
      double s = z[i];
      for (int k = i + 1; k < kDims; ++k) s -= l[k][i] * x[k];
      x[i] = s / l[i][i];
    }
    x0[c] = x[0];
  }
  return true;
}

// Denoises the illumination of rows [y0, y1) into out (3 channels a pixel, the whole image's layout).
void denoise_band(const Inputs& in, const RegressionDenoiserOptions& o, int y0, int y1, float* out) {
  const int w = in.width, h = in.height, r = o.window_radius, f = o.patch_radius;
  const int side = 2 * r + 1;
  const int ya = std::max(0, y0 - f), yb = std::min(h, y1 + f);  // the band and the patches' halo
  const size_t band = static_cast<size_t>(y1 - y0) * static_cast<size_t>(w);
  const float k2 = o.strength * o.strength;
  std::vector<float> weights(static_cast<size_t>(side * side) * band);
  std::vector<float> delta(static_cast<size_t>(yb - ya) * static_cast<size_t>(w));
  std::vector<float> rows(delta.size());

  // The per-pixel term of the patch distance between p and its neighbour q = p + (dx, dy) (q clamped to the image,
  // so that patches near the border are whole; a q outside the image gets no weight below).
  auto term = [&](size_t p, size_t q) {
    float s = 0;
    for (int c = 0; c < 3; ++c) {
      const float vp = in.v[c][p], vq = in.v[c][q], d = in.y[c][p] - in.y[c][q];
      s += (d * d - (vp + std::min(vp, vq))) / (1e-10f + k2 * (vp + vq));
    }
    return s;
  };
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx) {
      for (int row = ya; row < yb; ++row) {
        const int qy = std::clamp(row + dy, 0, h - 1);
        const size_t p0 = static_cast<size_t>(row) * static_cast<size_t>(w);
        const size_t q0 = static_cast<size_t>(qy) * static_cast<size_t>(w);
        float* d = &delta[static_cast<size_t>(row - ya) * static_cast<size_t>(w)];
        const int lo = std::clamp(-dx, 0, w), hi = std::clamp(w - dx, lo, w);
        for (int x = 0; x < lo; ++x) d[x] = term(p0 + static_cast<size_t>(x), q0);
        for (int x = lo; x < hi; ++x) d[x] = term(p0 + static_cast<size_t>(x), q0 + static_cast<size_t>(x + dx));
        for (int x = hi; x < w; ++x) d[x] = term(p0 + static_cast<size_t>(x), q0 + static_cast<size_t>(w - 1));
        // The patch's horizontal sums.
        float* s = &rows[static_cast<size_t>(row - ya) * static_cast<size_t>(w)];
        for (int x = 0; x < w; ++x) {
          float sum = 0;
          for (int i = std::max(0, x - f); i <= std::min(w - 1, x + f); ++i) sum += d[i];
          s[x] = sum;
        }
      }
      float* wt = &weights[static_cast<size_t>((dy + r) * side + (dx + r)) * band];
      for (int row = y0; row < y1; ++row) {
        const int r0 = std::max(ya, row - f), r1 = std::min(yb - 1, row + f);
        const bool inside_y = row + dy >= 0 && row + dy < h;
        for (int x = 0; x < w; ++x) {
          float sum = 0;
          for (int i = r0; i <= r1; ++i) sum += rows[static_cast<size_t>(i - ya) * static_cast<size_t>(w) + x];
          const int cols = std::min(w - 1, x + f) - std::max(0, x - f) + 1;
          const float d2 = sum / static_cast<float>(3 * cols * (r1 - r0 + 1));
          const bool inside = inside_y && x + dx >= 0 && x + dx < w;
          const float weight = inside ? std::exp(-std::max(0.0f, d2)) : 0.0f;
          wt[static_cast<size_t>(row - y0) * static_cast<size_t>(w) + x] = weight < kMinWeight ? 0.0f : weight;
        }
      }
    }

  for (int row = y0; row < y1; ++row)
    for (int x = 0; x < w; ++x) {
      const size_t p = static_cast<size_t>(row) * static_cast<size_t>(w) + static_cast<size_t>(x);
      const size_t bi = static_cast<size_t>(row - y0) * static_cast<size_t>(w) + static_cast<size_t>(x);
      const std::array<float, 4>& fp = in.features[p];
      double a[kDims][kDims] = {}, b[3][kDims] = {};
      for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx) {
          const double wq = weights[static_cast<size_t>((dy + r) * side + (dx + r)) * band + bi];
          if (wq == 0) continue;
          const size_t q = static_cast<size_t>(static_cast<std::ptrdiff_t>(p) + dy * w + dx);
          const std::array<float, 4>& fq = in.features[q];
          const double xs[kDims] = {1.0, fq[0] - fp[0], fq[1] - fp[1], fq[2] - fp[2], fq[3] - fp[3]};
          for (int i = 0; i < kDims; ++i) {
            const double wx = wq * xs[i];
            for (int j = i; j < kDims; ++j) a[i][j] += wx * xs[j];
            for (int c = 0; c < 3; ++c) b[c][i] += wx * in.y[c][q];
          }
        }
      for (int i = 1; i < kDims; ++i) a[i][i] += kRidge * a[0][0];
      double x0[3];
      if (!solve_intercepts(a, b, x0))
        for (int c = 0; c < 3; ++c) x0[c] = b[c][0] / a[0][0];  // the weighted mean
      for (int c = 0; c < 3; ++c) out[3 * p + static_cast<size_t>(c)] = static_cast<float>(std::max(0.0, x0[c]));
    }
}

}  // namespace

const std::vector<std::string>& denoiser_features(Denoiser d) {
  static const std::vector<std::string> none, regression = {"albedo", "normal", "depth", "variance"};
  return d == Denoiser::kRegression ? regression : none;
}

void RegressionDenoiser::apply(Image& image) const {
  const ImageLayer& albedo = layer_named(image, "albedo", 3);
  const ImageLayer& normal = layer_named(image, "normal", 3);
  const ImageLayer& depth = layer_named(image, "depth", 1);
  const ImageLayer& variance = layer_named(image, "variance", 3);
  const std::vector<float>& beauty = image.beauty().pixels;
  Inputs in;
  in.width = image.width;
  in.height = image.height;
  const size_t n = static_cast<size_t>(image.width) * static_cast<size_t>(image.height);
  float far = 0;
  for (float z : depth.pixels)
    if (std::isfinite(z)) far = std::max(far, z);
  in.features.resize(n);
  for (int c = 0; c < 3; ++c) {
    in.y[c].resize(n);
    in.v[c].resize(n);
  }
  std::vector<float> divisor(3 * n);
  for (size_t i = 0; i < n; ++i) {
    // The samples that escaped add 0 to the albedo and normal passes but see the environment unmodulated: they count
    // as albedo 1, so that a pixel on an object's silhouette has the illumination of both sides. The share of the
    // pixel's samples that hit a surface is the length of its mean normal (unit normals of one surface).
    const float* nm = &normal.pixels[3 * i];
    const float covered = std::min(1.0f, std::sqrt(nm[0] * nm[0] + nm[1] * nm[1] + nm[2] * nm[2]));
    for (int c = 0; c < 3; ++c) {
      const size_t k = 3 * i + static_cast<size_t>(c);
      const float a = std::max(albedo.pixels[k] + (1 - covered), kAlbedoFloor);
      divisor[k] = a;
      in.y[c][i] = beauty[k] / a;
      // Unknown below 2 samples (infinite): as large as floats allow, so that every neighbour weighs 1.
      const float v = std::isfinite(variance.pixels[k]) ? variance.pixels[k] : 1e30f;
      in.v[c][i] = std::min(v / (a * a), 1e30f);
      in.features[i][static_cast<size_t>(c)] = normal.pixels[k];
    }
    // Escaped rays (infinite depth) as the farthest surface.
    in.features[i][3] = far > 0 ? (std::isfinite(depth.pixels[i]) ? depth.pixels[i] / far : 1.0f) : 0.0f;
  }

  std::vector<float> illumination(3 * n);
  const size_t bands = static_cast<size_t>((image.height + kBandRows - 1) / kBandRows);
  run_in_parallel(
      bands,
      [&](size_t i) {
        const int y0 = static_cast<int>(i) * kBandRows;
        denoise_band(in, options_, y0, std::min(image.height, y0 + kBandRows), illumination.data());
      },
      options_.threads);

  ImageLayer noisy{"noisy", {"R", "G", "B"}, beauty, false};
  for (size_t k = 0; k < 3 * n; ++k) illumination[k] *= divisor[k];
  image.layers.front().pixels = std::move(illumination);
  image.layers.insert(image.layers.begin() + 1, std::move(noisy));
}

std::shared_ptr<const PostStage> make_denoiser(Denoiser d, unsigned threads) {
  if (d == Denoiser::kRegression)
    return std::make_shared<RegressionDenoiser>(RegressionDenoiserOptions{.threads = threads});
  return nullptr;
}

}  // namespace tessera
