// Per-pixel adaptive sampling: which pixels of a render keep sampling.
//
// A pixel stops when its error estimate, and that of every pixel of its 3x3 neighbourhood, is at or below the
// render's threshold (render.adaptive_threshold). The estimate is the standard error of the pixel's mean luminance,
// from its own samples (the film's sum and sum of squares of luminance), relative to the square root of that mean
// below 1 and to the mean itself above:
//
//   e = sqrt(s² / n) / d(L),   s² = (Σ l² − n L²) / (n − 1),   d(L) = sqrt(max(L, 1e-4)) for L < 1, L for L ≥ 1
//
// with n the pixel's samples, l a sample's luminance and L their mean. Dividing by sqrt(L) below 1 is the stopping
// condition of Dammertz, Hanika, Keller and Lensch 2010 ("A hierarchical automatic stopping condition for Monte Carlo
// global illumination", WSCG), which Cycles follows: the eye sees noise in dark regions more than a relative error
// says. Above 1 a display clamps or compresses the value, so its relative error is what shows. Dammertz et al. and
// Cycles estimate the error as the difference between the mean of all samples and of half of them; the film keeps no
// half buffer of the beauty, and the sample variance of the mean measures the same spread (the half-buffer difference
// is, in expectation, that standard error times a constant) without a second buffer. Spreading the decision to the
// neighbours keeps a pixel that happens to look converged amid noise sampling (Dammertz et al. decide over blocks for
// the same reason).
//
// Decisions are taken only at fixed sample counts, the decision points min_spp, 2 min_spp, 3 min_spp … below spp,
// which depend on the job alone: the image is the same bits whatever the thread count, the pass sizes or a resume.
// Between two decision points the pixels that sample are exactly those whose count is the film's samples() (the
// others stopped at an earlier decision point), so a film holds all the state a resume needs.
//
// A render of a sample range of a larger job (a work unit, RenderSettings::first_sample, job_spp) decides from its
// own samples alone, so that units merge in any order to the same image: its standard errors are those of fewer
// samples, so its threshold is the job's times sqrt(job samples / unit samples), and its min_spp the job's share of
// min_spp (rounded up). A pixel whose units each stop at their threshold then has about the job's error when merged,
// as Cycles scales the threshold of a sample subset for the same reason.
#pragma once

#include <cstdint>
#include <vector>

#include "renderer/film.h"
#include "renderer/integrator.h"
#include "renderer/render_settings.h"

namespace tessera {

class AdaptiveSampling {
 public:
  AdaptiveSampling() = default;
  // For a render of `settings` (its spp samples, of a job of settings.budget() samples).
  explicit AdaptiveSampling(const RenderSettings& settings);

  bool enabled() const { return threshold_ > 0; }
  // This render's threshold and minimum samples (a unit's, scaled from the job's).
  double threshold() const { return threshold_; }
  uint32_t min_spp() const { return min_spp_; }
  // Whether `n` samples is a decision point.
  bool is_decision_point(uint32_t n) const { return enabled() && n >= min_spp_ && n % min_spp_ == 0 && n < spp_; }
  // The first decision point after `n` samples (spp when there is none before it).
  uint32_t next_decision_point(uint32_t n) const;

  // The pixels of `region` that sample in the pass starting at the film's samples(): 1 in `active` (the whole image's
  // size, row-major) for each. At a decision point, those of count samples() whose neighbourhood's error is above the
  // threshold; otherwise those of count samples(). Returns how many there are.
  size_t active_pixels(const Film& film, const PixelRegion& region, PixelMask& active) const;

  // The error estimate of pixel `i` of `film` (above); infinite for fewer than 2 samples.
  static double pixel_error(const Film& film, size_t i);

 private:
  double threshold_ = 0;
  uint32_t min_spp_ = 1;
  uint32_t spp_ = 0;
};

}  // namespace tessera
