// Phase functions: the angular distribution of light scattered at a point of a participating medium, the medium's
// counterpart of a BSDF (Pharr, Jakob and Humphreys, Physically Based Rendering, 4th ed., §11.3). A phase function is
// a normalised density over the sphere of directions, so that sampling it exactly gives the path weight 1.
//
// Conventions as for the BSDFs (renderer/bsdf/bsdf.h): `wo` points back to where the path came from, `wi` to where light comes
// from; both are unit vectors in world space. Light travelling along -wi is scattered into wo, so the scattering
// angle theta, between the directions of travel before and after, has cos theta = dot(-wi, wo) = dot(-wo, wi).
#pragma once

#include <cmath>

#include "renderer/math.h"

namespace tessera {

struct PhaseSample {
  Vec3 wi;
  float pdf = 0;  // equal to the phase function's value: the weight p / pdf is 1
};

// The Henyey–Greenstein phase function (Henyey and Greenstein 1941, "Diffuse radiation in the galaxy"; PBR 4th ed.,
// §11.3.1): p(cos theta) = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos theta)^(3/2)), with cos theta the cosine between the
// direction of travel before and after scattering and g in (-1, 1) the mean of cos theta: g > 0 scatters forwards,
// g < 0 backwards, g = 0 uniformly.
class HenyeyGreenstein {
 public:
  explicit HenyeyGreenstein(float g) : g_(g) {}
  float g() const { return g_; }

  // The density of scattering by angle theta, per steradian.
  static float density(float cos_theta, float g) {
    const float denom = 1 + g * g - 2 * g * cos_theta;
    return (1 - g * g) / (4 * kPi * denom * std::sqrt(std::max(denom, 1e-12f)));
  }

  // p(wo, wi), per steradian of wi; symmetric in its arguments.
  float p(const Vec3& wo, const Vec3& wi) const { return density(dot(-wo, wi), g_); }
  float pdf(const Vec3& wo, const Vec3& wi) const { return p(wo, wi); }

  // Samples wi by inverting the cumulative distribution of cos theta (PBR 4th ed., §11.3.1, equation 11.13), about
  // the direction of travel -wo, with phi uniform. `u` uniform in [0, 1)^2.
  PhaseSample sample(const Vec3& wo, Vec2 u) const {
    float cos_theta;
    if (std::abs(g_) < 1e-3f) {
      cos_theta = 1 - 2 * u.x;
    } else {
      const float sq = (1 - g_ * g_) / (1 - g_ + 2 * g_ * u.x);
      cos_theta = (1 + g_ * g_ - sq * sq) / (2 * g_);
    }
    cos_theta = clamp(cos_theta, -1.0f, 1.0f);
    const float sin_theta = std::sqrt(std::max(0.0f, 1 - cos_theta * cos_theta));
    const float phi = 2 * kPi * u.y;
    const Frame frame = Frame::from_normal(-wo);
    const Vec3 wi = normalize(frame.to_world(Vec3(sin_theta * std::cos(phi), sin_theta * std::sin(phi), cos_theta)));
    return {wi, density(cos_theta, g_)};
  }

 private:
  float g_;
};

}  // namespace tessera
