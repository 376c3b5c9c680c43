// Participating media: what light meets between surfaces. A medium fills the inside of a closed surface: a path
// refracted in through the surface's front side travels in its material's interior medium until it refracts out
// through a back side (Pharr, Jakob and Humphreys, Physically Based Rendering, 4th ed., §11.4, medium interfaces).
//
// A homogeneous medium absorbs (sigma_a) and scatters (sigma_s) the same everywhere; along a segment of length d the
// radiance falls by the transmittance exp(-sigma_t d) per channel, sigma_t = sigma_a + sigma_s (Beer–Lambert's law,
// PBR 4th ed. §11.2; Jensen et al. 2001, §2). A medium that only absorbs attenuates a path; one that scatters is where
// a path may also turn, by its phase function (phase.h), at a distance sampled by free-flight sampling.
#pragma once

#include <algorithm>
#include <cmath>
#include <memory>

#include "renderer/math.h"
#include "renderer/phase.h"
#include "renderer/sampler.h"

namespace tessera {

// One sampled free flight along a ray through a medium (PBR 4th ed. §14.1.2, homogeneous media).
struct FreeFlight {
  bool scattered = false;  // a real scattering event at distance t; otherwise the ray crossed the whole segment
  float t = 0;             // distance (scene units) from the ray's origin to the scattering event
  // The path weight: T(t) sigma_s / pdf(t) at a scattering event, T(t_max) / P(t_max) when the segment was crossed
  // (pdf and P those of free_flight_pdf and crossing_probability).
  Rgb weight{1};
};

// Random numbers for the stochastic estimators of heterogeneous media (delta and ratio tracking draw as many as the
// ray has tentative collisions, which no fixed layout of sampler dimensions can hold): a SplitMix64 stream (Steele,
// Lea and Flood 2014) that a path seeds once and carries along. Homogeneous media draw none of them.
class MediumRng {
 public:
  explicit MediumRng(uint64_t seed = 0) : state_(seed) {}
  // Next uniform number in [0, 1).
  float next() {
    state_ += 0x9e3779b97f4a7c15ULL;
    return static_cast<float>(mix64(state_) >> 40) * 0x1p-24f;
  }

 private:
  uint64_t state_;
};

class Medium {
 public:
  virtual ~Medium() = default;
  // The fraction of radiance, per channel, that crosses the first `distance` scene units (infinity allowed) of `ray`
  // (its direction of any length: distances are along the unit direction) in the medium; an estimate whose expected
  // value is that fraction for a heterogeneous medium, drawing its numbers from `rng`.
  virtual Rgb transmittance(const Ray& ray, float distance, MediumRng& rng) const = 0;
  // Whether light scatters in the medium (sigma_s above zero in some channel): only then do paths sample free flights
  // through it and scatter in it; otherwise they are attenuated by the transmittance alone.
  virtual bool scatters() const = 0;
  // Samples where along the first t_max scene units of `ray` (infinity allowed; distances along its unit direction)
  // the path first interacts, for a path of throughput `throughput` (which chooses the channel to sample by);
  // `u` uniform in [0, 1), the first number, and `rng` the further numbers a heterogeneous medium draws.
  virtual FreeFlight sample_free_flight(const Ray& ray, float t_max, const Rgb& throughput, float u,
                                        MediumRng& rng) const = 0;
  // The phase function at a scattering event.
  virtual HenyeyGreenstein phase() const = 0;
  // Whether the coefficients are the same everywhere (transmittance in closed form, free flights from one number).
  virtual bool homogeneous() const { return true; }
  // True for the interior of a subsurface material (subsurface.h): dense, bright and entered through its surface;
  // the path tracer random-walks in it without the Russian roulette floor it keeps elsewhere.
  bool subsurface() const { return subsurface_; }

 protected:
  bool subsurface_ = false;
};

// A medium of the same coefficients everywhere: sigma_a and sigma_s per scene unit and per channel, and a
// Henyey–Greenstein phase function of asymmetry g.
//
// A chromatic medium (sigma_t differing by channel) cannot sample one free-flight distance that suits every channel.
// A channel is chosen with probability proportional to the path's throughput times the channel's single-scattering
// albedo, the distance is sampled from that channel's exponential, and the sample is weighted by the mixture of all
// channels' densities: the one-sample model of multiple importance sampling with the balance heuristic over the
// channels (Veach 1997, §9.2.4; Chiang, Kutz and Burley 2016, "Practical and controllable subsurface scattering for
// production path tracing", §4; PBR 4th ed. §14.1.3). The estimate is unbiased for every channel whatever the
// probabilities, as long as the mixture density is positive wherever a channel's integrand is.
class HomogeneousMedium final : public Medium {
 public:
  explicit HomogeneousMedium(const Rgb& sigma_a, const Rgb& sigma_s = Rgb(0), float g = 0, bool subsurface = false)
      : sigma_a_(sigma_a), sigma_s_(sigma_s), sigma_t_(sigma_a + sigma_s), g_(g) {
    subsurface_ = subsurface;
  }
  const Rgb& sigma_a() const { return sigma_a_; }
  const Rgb& sigma_s() const { return sigma_s_; }
  const Rgb& sigma_t() const { return sigma_t_; }
  float g() const { return g_; }

  // exp(-sigma_t distance) per channel.
  Rgb transmittance(float distance) const {
    return Rgb(channel_transmittance(sigma_t_.x, distance), channel_transmittance(sigma_t_.y, distance),
               channel_transmittance(sigma_t_.z, distance));
  }
  Rgb transmittance(const Ray&, float distance, MediumRng&) const override { return transmittance(distance); }
  bool scatters() const override { return sigma_s_.x > 0 || sigma_s_.y > 0 || sigma_s_.z > 0; }
  HenyeyGreenstein phase() const override { return HenyeyGreenstein(g_); }

  // The probabilities of sampling the distance by each channel: throughput times albedo sigma_s / sigma_t, normalised;
  // by the throughput alone where that is zero everywhere, and uniform where the throughput is too.
  Rgb channel_pmf(const Rgb& throughput) const {
    Rgb w;
    for (int c = 0; c < 3; ++c)
      w[c] = sigma_t_[c] > 0 ? std::max(0.0f, throughput[c]) * (sigma_s_[c] / sigma_t_[c]) : 0.0f;
    float sum = w.x + w.y + w.z;
    if (!(sum > 0) || !std::isfinite(sum)) {
      for (int c = 0; c < 3; ++c) w[c] = std::max(0.0f, throughput[c]);
      sum = w.x + w.y + w.z;
    }
    if (!(sum > 0) || !std::isfinite(sum)) return Rgb(1.0f / 3);
    return w / sum;
  }
  // The density, per scene unit, of a first interaction at distance t when channels are chosen by `pmf`:
  // sum over channels of pmf_c sigma_t,c exp(-sigma_t,c t).
  float free_flight_pdf(float t, const Rgb& pmf) const {
    float pdf = 0;
    for (int c = 0; c < 3; ++c) pdf += pmf[c] * sigma_t_[c] * channel_transmittance(sigma_t_[c], t);
    return pdf;
  }
  // The probability that no interaction is sampled before t_max: sum over channels of pmf_c exp(-sigma_t,c t_max).
  float crossing_probability(float t_max, const Rgb& pmf) const {
    float p = 0;
    for (int c = 0; c < 3; ++c) p += pmf[c] * channel_transmittance(sigma_t_[c], t_max);
    return p;
  }

  FreeFlight sample_free_flight(const Ray&, float t_max, const Rgb& throughput, float u, MediumRng&) const override {
    return sample_free_flight(t_max, throughput, u);
  }
  FreeFlight sample_free_flight(float t_max, const Rgb& throughput, float u) const {
    const Rgb pmf = channel_pmf(throughput);
    // The channel by u, and u rescaled within its interval for the distance.
    int c = 0;
    float lo = 0;
    while (c < 2 && u >= lo + pmf[c]) lo += pmf[c++];
    const float u_dist = std::min((u - lo) / pmf[c], 0x1.fffffep-1f);
    FreeFlight ff;
    const float t = sigma_t_[c] > 0 ? -std::log1p(-u_dist) / sigma_t_[c] : kInfinity;
    if (t < t_max) {
      const float pdf = free_flight_pdf(t, pmf);
      if (!(pdf > 0)) return FreeFlight{false, t_max, Rgb(0)};
      ff.scattered = true;
      ff.t = t;
      ff.weight = transmittance(t) * sigma_s_ / pdf;
    } else {
      const float p = crossing_probability(t_max, pmf);
      ff.t = t_max;
      ff.weight = p > 0 ? transmittance(t_max) / p : Rgb(0);
    }
    return ff;
  }

 private:
  // exp(-sigma d) of one channel; a channel that does not interact transmits everything, even over an infinite
  // distance.
  static float channel_transmittance(float sigma, float distance) {
    return sigma > 0 ? std::exp(-sigma * distance) : 1.0f;
  }

  Rgb sigma_a_, sigma_s_, sigma_t_;
  float g_;
};

// The absorbing medium that turns white light `color` (each channel in (0, 1]) after `distance` scene units inside:
// sigma_a = -ln(color) / distance, the parameterisation of glTF's KHR_materials_volume (attenuationColor,
// attenuationDistance) and of the JSON materials' attenuation_color and attenuation_distance. Channels below 1e-6 are
// taken as 1e-6 (a finite absorption), and a distance that is not positive gives no medium.
inline std::shared_ptr<const HomogeneousMedium> absorbing_medium(const double (&color)[3], double distance) {
  if (!(distance > 0)) return nullptr;
  Rgb sigma_a;
  for (int c = 0; c < 3; ++c) sigma_a[c] = static_cast<float>(-std::log(std::clamp(color[c], 1e-6, 1.0)) / distance);
  return std::make_shared<HomogeneousMedium>(sigma_a);
}

// The medium a path is in, followed from surface to surface; every integrator's walks keep one. A path starts in the
// medium around the scene's objects (`outside`; null: vacuum), where the camera and the lights sit.
class MediumTracker {
 public:
  explicit MediumTracker(const Medium* outside = nullptr) : current_(outside), outside_(outside) {}
  // A tracker that starts in `current` rather than around the objects (a path's later vertex).
  static MediumTracker starting_in(const Medium* current, const Medium* outside) {
    MediumTracker t(outside);
    t.current_ = current;
    return t;
  }
  const Medium* current() const { return current_; }
  const Medium* outside() const { return outside_; }
  // The path went `t` along `ray` (its direction not normalised: t is in units of its length) inside the current
  // medium: the throughput takes that segment's transmittance (estimated with `rng` in a heterogeneous medium).
  void attenuate(Rgb& throughput, const Ray& ray, float t, MediumRng& rng) const {
    if (current_) throughput *= current_->transmittance(ray, t * length(ray.dir), rng);
  }
  // The path refracted through a surface of a material whose inside is `interior` (null: none): in through the front
  // side it enters it, out through the back side it leaves into the medium around the objects (objects do not nest
  // media).
  void refract(bool front_face, const Medium* interior) { current_ = front_face ? interior : outside_; }

 private:
  const Medium* current_ = nullptr;
  const Medium* outside_ = nullptr;
};

}  // namespace tessera
