#include "renderer/material/subsurface.h"

#include <algorithm>
#include <cmath>

#include "renderer/material/material.h"
#include "renderer/scene_error.h"

namespace tessera {

double subsurface_single_scattering_albedo(double multiscatter_albedo, double g) {
  const double a = std::clamp(multiscatter_albedo, 0.0, 1.0);
  // In double: near A = 1 the square root nearly cancels the rest.
  const double s = std::clamp(4.09712 + 4.20863 * a - std::sqrt(9.59217 + 41.6808 * a + 17.7126 * a * a), 0.0, 1.0);
  const double s2 = s * s;
  return std::clamp((1 - s2) / (1 - g * s2), 0.0, 1.0);
}

std::shared_ptr<const Medium> subsurface_medium(const SubsurfaceParams& p) {
  Rgb sigma_a, sigma_s;
  for (int c = 0; c < 3; ++c) {
    const double sigma_t = 1.0 / (static_cast<double>(p.radius) * p.radius_scale[c]);
    const double alpha = subsurface_single_scattering_albedo(p.color[c], p.anisotropy);
    sigma_s[c] = static_cast<float>(alpha * sigma_t);
    sigma_a[c] = static_cast<float>((1 - alpha) * sigma_t);
  }
  return std::make_shared<HomogeneousMedium>(sigma_a, sigma_s, p.anisotropy, true);
}

SubsurfaceParams read_subsurface(const nlohmann::json& j, const std::string& pointer, bool with_weight) {
  SubsurfaceParams p;
  if (with_weight) p.weight = params::number(j, "subsurface_weight", pointer, 0.0f, 0.0f, 1.0f);
  p.color = params::rgb(j, "subsurface_color", pointer, p.color, 0.0f, 1.0f);
  // A mean free path of zero would be an infinitely dense medium; 1e-6 scene units is the smallest taken.
  p.radius = params::number(j, "subsurface_radius", pointer, p.radius, 1e-6f, 1e9f);
  p.radius_scale = params::rgb(j, "subsurface_radius_scale", pointer, p.radius_scale, 1e-6f, 1e9f);
  p.anisotropy = params::number(j, "subsurface_scatter_anisotropy", pointer, 0.0f, -1.0f, 1.0f);
  // |g| = 1 is a delta phase function, not a Henyey–Greenstein lobe.
  if (!(std::abs(p.anisotropy) < 1))
    throw SceneError(pointer + "/subsurface_scatter_anisotropy", "must lie strictly between -1 and 1");
  return p;
}

}  // namespace tessera
