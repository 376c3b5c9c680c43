#include "renderer/denoise.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

// Eigen's scalar code, compiled without fused multiply-adds as the rest of the renderer is: its vectorised kernels
// would fuse them where the processor has FMA, and the denoised image would then depend on the build's processor.
#define EIGEN_DONT_VECTORIZE
#include <Eigen/Cholesky>
#include <Eigen/Core>

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
  std::array<std::vector<float>, 3> y;  // the illumination
  std::array<std::vector<float>, 3> v;  // its variance
  std::array<std::vector<float>, 4> f;  // the features: normal, depth over the image's largest finite depth
};

// Solves A x = b for a symmetric positive definite A (kDims x kDims, upper triangle given) for three right-hand
// sides by its Cholesky factorisation (Eigen's LLT; Golub and Van Loan, Matrix Computations, 4th ed., 2013, §4.2), and
// returns x[0] of each; false when A is not numerically positive definite (a flat or degenerate window: the caller
// keeps the pixel's own estimate).
bool solve_intercepts(const double (&a)[kDims][kDims], const double (&b)[3][kDims], double (&x0)[3]) {
  Eigen::Matrix<double, kDims, kDims> m;
  for (int i = 0; i < kDims; ++i)
    for (int j = i; j < kDims; ++j) m(i, j) = m(j, i) = a[i][j];
  const Eigen::LLT<Eigen::Matrix<double, kDims, kDims>> llt(m);
  if (llt.info() != Eigen::Success || !(llt.rcond() > 1e-12)) return false;
  Eigen::Matrix<double, kDims, 3> rhs;
  for (int c = 0; c < 3; ++c)
    for (int i = 0; i < kDims; ++i) rhs(i, c) = b[c][i];
  const Eigen::Matrix<double, kDims, 3> x = llt.solve(rhs);
  for (int c = 0; c < 3; ++c) x0[c] = x(0, c);
  return true;
}

// Element-wise loops over arrays that do not overlap, which the compiler vectorises.
void difference(float* __restrict out, const float* __restrict a, const float* __restrict b, size_t n) {
  for (size_t i = 0; i < n; ++i) out[i] = a[i] - b[i];
}
void product(float* __restrict out, const float* __restrict a, const float* __restrict b, size_t n) {
  for (size_t i = 0; i < n; ++i) out[i] = a[i] * b[i];
}
void add(float* __restrict acc, const float* __restrict a, size_t n) {
  for (size_t i = 0; i < n; ++i) acc[i] += a[i];
}
void add_product(float* __restrict acc, const float* __restrict a, const float* __restrict b, size_t n) {
  for (size_t i = 0; i < n; ++i) acc[i] += a[i] * b[i];
}

// Denoises the illumination of rows [y0, y1) into out (3 channels a pixel, the whole image's layout). Offset by
// offset of the window, the weights of a row's pixels are worked out and added with their neighbours' terms to the
// row's sums of the normal equations: the loops run along rows, over contiguous arrays.
void denoise_band(const Inputs& in, const RegressionDenoiserOptions& o, int y0, int y1, float* out) {
  const int w = in.width, h = in.height, r = o.window_radius, f = o.patch_radius;
  const int ya = std::max(0, y0 - f), yb = std::min(h, y1 + f);  // the band and the patches' halo
  const size_t W = static_cast<size_t>(w), band = static_cast<size_t>(y1 - y0) * W;
  const float k2 = o.strength * o.strength;
  std::vector<float> delta(static_cast<size_t>(yb - ya) * W), rows(delta.size()), weight(W);
  std::vector<float> regressors(static_cast<size_t>(kDims) * W), weighted(static_cast<size_t>(kDims) * W);
  // The normal equations' sums per pixel of the band: the upper triangle of sum w x x^T (kTerms), then sum w x y_c
  // for each channel (3 kDims), each as an array over the band.
  // The arrays are 64 floats apart beyond the band's size: arrays a multiple of 4 KiB apart would share cache sets.
  constexpr int kTerms = kDims * (kDims + 1) / 2;
  const size_t stride = band + 64;
  std::vector<float> sums(static_cast<size_t>(kTerms + 3 * kDims) * stride, 0.0f);

  // The per-pixel term of the patch distance between p and its neighbour q = p + (dx, dy) (q clamped to the image,
  // so that patches near the border are whole; a q outside the image gets no weight below).
  const float* __restrict y[3] = {in.y[0].data(), in.y[1].data(), in.y[2].data()};
  const float* __restrict v[3] = {in.v[0].data(), in.v[1].data(), in.v[2].data()};
  const float* __restrict fe[4] = {in.f[0].data(), in.f[1].data(), in.f[2].data(), in.f[3].data()};
  auto term = [&](size_t p, size_t q) {
    float s = 0;
    for (int c = 0; c < 3; ++c) {
      const float vp = v[c][p], vq = v[c][q], d = y[c][p] - y[c][q];
      s += (d * d - (vp + std::min(vp, vq))) / (1e-10f + k2 * (vp + vq));
    }
    return s;
  };
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx) {
      const int lo = std::clamp(-dx, 0, w), hi = std::clamp(w - dx, lo, w);  // the x whose q is inside
      for (int row = ya; row < yb; ++row) {
        const int qy = std::clamp(row + dy, 0, h - 1);
        const size_t p0 = static_cast<size_t>(row) * W, q0 = static_cast<size_t>(qy) * W;
        float* __restrict d = &delta[static_cast<size_t>(row - ya) * W];
        for (int x = 0; x < lo; ++x) d[x] = term(p0 + static_cast<size_t>(x), q0);
        for (int x = lo; x < hi; ++x) d[x] = term(p0 + static_cast<size_t>(x), q0 + static_cast<size_t>(x + dx));
        for (int x = hi; x < w; ++x) d[x] = term(p0 + static_cast<size_t>(x), q0 + W - 1);
        // The patch's horizontal sums.
        float* s = &rows[static_cast<size_t>(row - ya) * W];
        for (int x = 0; x < w; ++x) {
          float sum = 0;
          for (int i = std::max(0, x - f); i <= std::min(w - 1, x + f); ++i) sum += d[i];
          s[x] = sum;
        }
      }
      for (int row = y0; row < y1; ++row) {
        if (row + dy < 0 || row + dy >= h) continue;
        const int r0 = std::max(ya, row - f), r1 = std::min(yb - 1, row + f);
        float* __restrict sum = weight.data();
        std::fill(weight.begin(), weight.end(), 0.0f);
        for (int i = r0; i <= r1; ++i) {
          const float* __restrict s = &rows[static_cast<size_t>(i - ya) * W];
          for (int x = lo; x < hi; ++x) sum[x] += s[x];
        }
        for (int x = lo; x < hi; ++x) {
          const int cols = std::min(w - 1, x + f) - std::max(0, x - f) + 1;
          const float d2 = sum[x] / static_cast<float>(3 * cols * (r1 - r0 + 1));
          const float wt = d2 < 7.0f ? std::exp(-std::max(0.0f, d2)) : 0.0f;
          sum[x] = wt < kMinWeight ? 0.0f : wt;
        }
        const size_t p0 = static_cast<size_t>(row) * W;
        const size_t q0 = static_cast<size_t>(static_cast<std::ptrdiff_t>(p0) +
                                              static_cast<std::ptrdiff_t>(dy) * static_cast<std::ptrdiff_t>(w) + dx);
        // Over the row's x whose q is inside: the regressors x_i (1, then the features' differences), w x_i, and
        // their products added to the sums.
        const size_t n = static_cast<size_t>(hi - lo), x0 = static_cast<size_t>(lo);
        const float* xs[kDims];
        float* wxs[kDims];
        xs[0] = nullptr;  // the constant 1
        for (int k = 1; k < kDims; ++k) {
          float* xk = &regressors[static_cast<size_t>(k) * W];
          difference(xk, fe[k - 1] + q0 + x0, fe[k - 1] + p0 + x0, n);
          xs[k] = xk;
        }
        for (int k = 0; k < kDims; ++k) {
          wxs[k] = &weighted[static_cast<size_t>(k) * W];
          if (k == 0)
            std::copy_n(sum + x0, n, wxs[0]);
          else
            product(wxs[k], sum + x0, xs[k], n);
        }
        float* acc = &sums[static_cast<size_t>(row - y0) * W + x0];
        int t = 0;
        for (int i = 0; i < kDims; ++i) {
          for (int j = i; j < kDims; ++j, ++t) {
            if (j == 0)
              add(acc + static_cast<size_t>(t) * stride, wxs[i], n);  // w * 1 * 1
            else
              add_product(acc + static_cast<size_t>(t) * stride, wxs[i], xs[j], n);
          }
          for (int c = 0; c < 3; ++c)
            add_product(acc + static_cast<size_t>(kTerms + c * kDims + i) * stride, wxs[i], y[c] + q0 + x0, n);
        }
      }
    }

  for (size_t bi = 0; bi < band; ++bi) {
    double a[kDims][kDims] = {}, b[3][kDims] = {};
    int t = 0;
    for (int i = 0; i < kDims; ++i) {
      for (int j = i; j < kDims; ++j) a[i][j] = sums[static_cast<size_t>(t++) * stride + bi];
      for (int c = 0; c < 3; ++c) b[c][i] = sums[static_cast<size_t>(kTerms + c * kDims + i) * stride + bi];
    }
    for (int i = 1; i < kDims; ++i) a[i][i] += kRidge * a[0][0];
    double x0[3];
    if (!solve_intercepts(a, b, x0))
      for (int c = 0; c < 3; ++c) x0[c] = b[c][0] / a[0][0];  // the weighted mean
    const size_t p = static_cast<size_t>(y0) * W + bi;
    for (int c = 0; c < 3; ++c) out[3 * p + static_cast<size_t>(c)] = static_cast<float>(std::max(0.0, x0[c]));
  }
}

}  // namespace

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
  for (std::vector<float>& feature : in.f) feature.resize(n);
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
      in.f[static_cast<size_t>(c)][i] = normal.pixels[k];
    }
    // Escaped rays (infinite depth) as the farthest surface.
    in.f[3][i] = far > 0 ? (std::isfinite(depth.pixels[i]) ? depth.pixels[i] / far : 1.0f) : 0.0f;
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
