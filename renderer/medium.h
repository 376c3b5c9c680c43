// Participating media: what light meets between surfaces. A medium fills the inside of a closed surface: a path
// refracted in through the surface's front side travels in its material's interior medium until it refracts out
// through a back side (Pharr, Jakob and Humphreys, Physically Based Rendering, 4th ed., §11.4, medium interfaces).
//
// The media here absorb and do not scatter: along a segment of length d the radiance falls by the transmittance
// exp(-sigma_a d) per channel, Beer–Lambert's law (PBR 4th ed. §11.2; Jensen et al. 2001, §2, the extinction of a
// medium with no scattering). The interface is where scattering media go: a free-flight distance and a phase function
// beside the transmittance.
#pragma once

#include <algorithm>
#include <cmath>
#include <memory>

#include "renderer/math.h"

namespace tessera {

class Medium {
 public:
  virtual ~Medium() = default;
  // The fraction of radiance, per channel, that crosses `distance` (scene units) of the medium.
  virtual Rgb transmittance(float distance) const = 0;
};

// A medium of the same absorption everywhere (sigma_a per scene unit, per channel).
class HomogeneousMedium final : public Medium {
 public:
  explicit HomogeneousMedium(const Rgb& sigma_a) : sigma_a_(sigma_a) {}
  const Rgb& sigma_a() const { return sigma_a_; }
  Rgb transmittance(float distance) const override {
    return Rgb(std::exp(-sigma_a_.x * distance), std::exp(-sigma_a_.y * distance), std::exp(-sigma_a_.z * distance));
  }

 private:
  Rgb sigma_a_;
};

// The absorbing medium that turns white light `color` (each channel in (0, 1]) after `distance` scene units inside:
// sigma_a = -ln(color) / distance, the parameterisation of glTF's KHR_materials_volume (attenuationColor,
// attenuationDistance) and of the JSON materials' attenuation_color and attenuation_distance. Channels below 1e-6 are
// taken as 1e-6 (a finite absorption), and a distance that is not positive gives no medium.
inline std::shared_ptr<const Medium> absorbing_medium(const double (&color)[3], double distance) {
  if (!(distance > 0)) return nullptr;
  Rgb sigma_a;
  for (int c = 0; c < 3; ++c) sigma_a[c] = static_cast<float>(-std::log(std::clamp(color[c], 1e-6, 1.0)) / distance);
  return std::make_shared<HomogeneousMedium>(sigma_a);
}

// The medium a path is in, followed from surface to surface; every integrator's walks keep one. A path starts in
// vacuum (the camera and the lights sit in no medium).
class MediumTracker {
 public:
  const Medium* current() const { return current_; }
  // The path went `t` along `ray` (its direction not normalised: t is in units of its length) inside the current
  // medium: the throughput takes that segment's transmittance.
  void attenuate(Rgb& throughput, const Ray& ray, float t) const {
    if (current_) throughput *= current_->transmittance(t * length(ray.dir));
  }
  // The path refracted through a surface of a material whose inside is `interior` (null: none): in through the front
  // side it enters it, out through the back side it leaves into vacuum (objects do not nest media).
  void refract(bool front_face, const Medium* interior) { current_ = front_face ? interior : nullptr; }

 private:
  const Medium* current_ = nullptr;
};

}  // namespace tessera
