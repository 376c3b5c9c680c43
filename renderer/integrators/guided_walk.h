// Guided random walks in a subsurface medium: Dwivedi sampling toward the surface the walk last met.
//
// A walk in a dense, bright medium (a subsurface material, subsurface.h) returns to the surface it entered by after
// many scatterings. The zero-variance theory of the half space (Křivánek and d'Eon 2014, "A zero-variance-based
// sampling scheme for Monte Carlo subsurface scattering") has its importance grow towards the surface as
// exp(z sigma_t / nu), nu the Dwivedi diffusion length of the single-scattering albedo: so directions are sampled
// from the Dwivedi phase function around the surface's outward normal n,
//   p(cos) = 1 / ((nu - cos) ln((nu + 1) / (nu - 1))) per unit cosine, the azimuth uniform
// (Meng, Hanika and Dachsbacher 2016, "Improving the Dwivedi sampling scheme", eqs. 9 and 10), and the distance
// along a direction of cosine cos with n from the stretched exponential of sigma_t (1 - cos / nu): walks head back
// to the surface in longer steps. nu comes from d'Eon and Křivánek 2020 ("Zero-variance theory for efficient
// subsurface scattering", eq. 67): nu = 1 / sqrt(1 - alpha^(2.44294 - 0.0215813 alpha + 0.578637 / alpha)).
//
// The guided and the classic technique (the phase function and sigma_t) are combined per step by the one-sample
// model of multiple importance sampling with the balance heuristic (Veach 1997, §9.2.4), over the two techniques and
// the three channels, each channel with its own nu and sigma_t: a channel is chosen by the medium's own pmf
// (HomogeneousMedium::channel_pmf), then the technique, the direction and the distance by that pair, and the step is
// weighted by the phase function and the transmittance over the mixture of all six densities. A step is so
// unbiased for any mixture; the guided fraction 1 - max(1/2, |g|^(1/8)) is Cycles' (guided steps are rarer the more
// anisotropic the medium).
#pragma once

#include <algorithm>
#include <cmath>

#include "renderer/math.h"
#include "renderer/medium.h"
#include "renderer/phase.h"

namespace tessera {

// What a medium's guided walks share: its Dwivedi diffusion lengths and the guided share, computed once per walk.
class GuidedWalk {
 public:
  explicit GuidedWalk(const HomogeneousMedium& medium) : medium_(&medium), guided_share_(guided_fraction(medium.g())) {
    for (int c = 0; c < 3; ++c) {
      const float st = medium.sigma_t()[c];
      nu_[c] = diffusion_length(st > 0 ? medium.sigma_s()[c] / st : 0.0f);
      log_ratio_[c] = std::log((nu_[c] + 1) / (nu_[c] - 1));
    }
  }

  // The Dwivedi diffusion length of single-scattering albedo `alpha` (d'Eon and Křivánek 2020, eq. 67), kept above 1
  // so that the phase function below stays a density.
  static float diffusion_length(float alpha) {
    alpha = std::clamp(alpha, 1e-3f, 0.999999f);
    const float nu =
        1 / std::sqrt(std::max(1e-12f, 1 - std::pow(alpha, 2.44294f - 0.0215813f * alpha + 0.578637f / alpha)));
    return std::max(nu, 1.0001f);
  }
  // The share of guided steps for a phase function of asymmetry g.
  static float guided_fraction(float g) { return 1 - std::max(0.5f, std::pow(std::abs(g), 0.125f)); }

  const HomogeneousMedium& medium() const { return *medium_; }
  float guided_share() const { return guided_share_; }
  float nu(int c) const { return nu_[c]; }
  // The guided technique's density of the cosine with the outward normal, for channel c's diffusion length.
  float dwivedi_density(int c, float cos) const { return 1 / ((nu_[c] - cos) * log_ratio_[c]); }
  // Its inverse cumulative distribution (Meng et al. 2016, eq. 10): cos = nu - (nu + 1) ((nu - 1) / (nu + 1))^u.
  float sample_dwivedi(int c, float u) const {
    return std::clamp(nu_[c] - (nu_[c] + 1) * std::exp(-u * log_ratio_[c]), -1.0f, 1.0f);
  }

 private:
  const HomogeneousMedium* medium_;
  float guided_share_;
  Rgb nu_, log_ratio_;  // per channel: nu and ln((nu + 1) / (nu - 1))
};

// One step of a guided walk: its direction, drawn at a scattering event, and the distance along it.
class GuidedWalkStep {
 public:
  // Samples the direction of the step after a scattering event at which the walk came along -wo, for a path of
  // `throughput`, `n` the outward normal of the surface the walk last met: `u_technique` chooses the channel and
  // the technique, `u` the direction.
  GuidedWalkStep(const GuidedWalk& walk, const Vec3& n, const Vec3& wo, const Rgb& throughput, float u_technique,
                 Vec2 u)
      : walk_(&walk), pmf_(walk.medium().channel_pmf(throughput)) {
    const HomogeneousMedium& medium = walk.medium();
    // The channel by u_technique, and u_technique rescaled within its interval for the technique.
    float lo = 0;
    while (channel_ < 2 && u_technique >= lo + pmf_[channel_]) lo += pmf_[channel_++];
    guided_ = pmf_[channel_] > 0 && (u_technique - lo) / pmf_[channel_] < walk.guided_share();
    const HenyeyGreenstein phase = medium.phase();
    if (guided_) {
      const float cos = walk.sample_dwivedi(channel_, u.x);
      const float sin = std::sqrt(std::max(0.0f, 1 - cos * cos));
      const float phi = 2 * kPi * u.y;
      wi_ = normalize(Frame::from_normal(n).to_world(Vec3(sin * std::cos(phi), sin * std::sin(phi), cos)));
    } else {
      wi_ = phase.sample(wo, u).wi;
    }
    phase_ = phase.p(wo, wi_);
    const float cos = clamp(dot(wi_, n), -1.0f, 1.0f);
    for (int c = 0; c < 3; ++c) {
      guided_pdf_[c] = walk.dwivedi_density(c, cos) * kInv2Pi;
      guided_sigma_[c] = medium.sigma_t()[c] * (1 - cos / walk.nu(c));
    }
  }

  const Vec3& wi() const { return wi_; }
  // The phase function's value at wi, per steradian.
  float phase() const { return phase_; }
  // The distance to the step's next scattering event, by the chosen channel and technique; `u` uniform in [0, 1).
  float sample_distance(float u) const {
    const float sigma = guided_ ? guided_sigma_[channel_] : walk_->medium().sigma_t()[channel_];
    return sigma > 0 ? -std::log1p(-std::min(u, 0x1.fffffep-1f)) / sigma : kInfinity;
  }

  // The path weight of the step: to a scattering event at distance t, or across t to the surface that cut the step
  // short (`scattered` false): the phase function times the transmittance (times sigma_s at a scattering event)
  // over the mixture of the six techniques' densities of the direction and the distance.
  Rgb weight(float t, bool scattered) const {
    const HomogeneousMedium& medium = walk_->medium();
    const float share = walk_->guided_share();
    Rgb transmittance;
    float pdf = 0;
    for (int c = 0; c < 3; ++c) {
      const float st = medium.sigma_t()[c];
      transmittance[c] = st > 0 ? std::exp(-st * t) : 1.0f;
      const float classic = phase_ * (scattered ? st : 1.0f) * transmittance[c];
      const float guided = guided_pdf_[c] * (scattered ? guided_sigma_[c] : 1.0f) *
                           (guided_sigma_[c] > 0 ? std::exp(-guided_sigma_[c] * t) : 1.0f);
      pdf += pmf_[c] * ((1 - share) * classic + share * guided);
    }
    if (!(pdf > 0) || !std::isfinite(pdf)) return Rgb(0);
    return transmittance * (scattered ? medium.sigma_s() : Rgb(1)) * (phase_ / pdf);
  }

 private:
  const GuidedWalk* walk_;
  Rgb pmf_;
  int channel_ = 0;
  bool guided_ = false;
  Vec3 wi_;
  float phase_ = 0;
  Rgb guided_pdf_, guided_sigma_;
};

}  // namespace tessera
