// Denoisers: post stages of the output pipeline (output.h) that replace the beauty by a denoised estimate and keep
// the beauty as it was rendered as the layer "noisy", as Blender keeps its "Noisy Image" pass.
//
// "regression" is a first-order regression on the feature passes with non-local-means weights, the core of
// NFOR (Bitterli, Rousselle, Moon, Iglesias-Guitián, Adler, Mitchell, Jarosz and Novák, "Nonlinear Weighted
// First-Order Regression for Denoising Monte Carlo Renderings", EGSR 2016), without its two half-buffers and its
// selection among several filters: the weights are guided by the per-pixel variance of the mean (the `variance` pass)
// instead, with the variance-cancelling patch distance of Rousselle, Knaus and Zwicker ("Adaptive Rendering with
// Non-Local Means Filtering", SIGGRAPH Asia 2012). Per pixel p:
//   1. the illumination y = beauty / a is what is filtered and a multiplied back, so that texture detail, which lives
//      in the albedo, is never blurred (the albedo demodulation of Schied et al., "Spatiotemporal Variance-Guided
//      Filtering", HPG 2017, and Bako et al., "Kernel-Predicting Convolutional Networks for Denoising Monte Carlo
//      Renderings", SIGGRAPH 2017). a is the albedo pass plus the share of samples that escaped (they see the
//      environment unmodulated: albedo 1; the share is 1 - |mean normal|), at least 0.01; y's variance is the
//      beauty's over a^2;
//   2. every pixel q of a (2R+1)^2 window gets the weight w = exp(-max(0, d^2)), d^2 the mean over a (2f+1)^2 patch
//      and the three channels of ((y_p - y_q)^2 - (v_p + min(v_p, v_q))) / (1e-10 + k^2 (v_p + v_q)): neighbours
//      whose difference the noise explains weigh 1, those across a shadow edge ~0;
//   3. the illumination is fit by weighted least squares to a linear function of the features' differences from
//      p's, y_q ~ b0 + b . (normal_q - normal_p, depth_q - depth_p) (depth over the image's farthest), with a small
//      ridge term (Tikhonov) on b; b0, the fit at p, is p's denoised illumination (clamped at 0), times a_p its
//      beauty.
// A noiseless image (variance 0) gives weight 0 to every neighbour that differs from p and comes out as it went in;
// a constant one comes out constant. Each pixel's sums run over the window in a fixed order, and rows are computed in
// fixed bands whatever the threads, so the result is the same bits on any thread count.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "renderer/image.h"
#include "renderer/render_settings.h"

namespace tessera {

struct RegressionDenoiserOptions {
  int window_radius = 6;   // R: the regression's window is (2R + 1)^2 pixels
  int patch_radius = 1;    // f: the NL-means patches are (2f + 1)^2 pixels
  float strength = 0.45f;  // k: larger smooths more
  unsigned threads = 0;    // run_in_parallel's: 0 every hardware thread
};

class RegressionDenoiser : public PostStage {
 public:
  explicit RegressionDenoiser(RegressionDenoiserOptions options = {}) : options_(options) {}
  const char* name() const override { return "regression"; }
  // Needs the layers albedo, normal, depth and variance (throws std::invalid_argument without them): the beauty
  // becomes the denoised image and the layer "noisy" (R, G, B), right after it, the beauty as it was.
  void apply(Image& image) const override;

 private:
  RegressionDenoiserOptions options_;
};

// The post stage of denoiser `d`, or null for Denoiser::kNone.
std::shared_ptr<const PostStage> make_denoiser(Denoiser d, unsigned threads = 0);

}  // namespace tessera
