// Subsurface scattering on materials: the artist parameters of OpenPBR's subsurface lobe (Andersson et al., OpenPBR
// Surface specification, 2024, "Subsurface") turned into the coefficients of the homogeneous medium inside the
// material's dielectric boundary (medium.h). The path tracer random-walks in that medium between entering and
// leaving the surface, as Cycles' random-walk subsurface and Mitsuba 3's medium behind a dielectric do.
//
// The parameters:
//   subsurface_color A   the multiple-scattering albedo: the total diffuse reflectance of a thick, index-matched slab
//                        of the medium under uniform light
//   subsurface_radius r  and subsurface_radius_scale s (RGB): the mean free path per channel, r s (scene units)
//   subsurface_scatter_anisotropy g   the Henyey–Greenstein phase function's
// are mapped, per channel, to
//   sigma_t = 1 / (r s),  sigma_s = alpha sigma_t,  sigma_a = (1 - alpha) sigma_t
// with the single-scattering albedo alpha found from A by inverting van de Hulst's fit of the albedo of a
// semi-infinite medium (H. C. van de Hulst, Multiple Light Scattering, 1980, vol. 2, §21; the same inversion gives
// Chiang, Kutz and Burley 2016, "Practical and controllable subsurface scattering for production path tracing",
// §3, their fit for g = 0):
//   A = (1 - s)(1 - 0.139 s) / (1 + 1.17 s),  s = sqrt((1 - alpha) / (1 - g alpha))
// solved for s (the root of 0.139 s^2 - (1.139 + 1.17 A) s + (1 - A) = 0 in [0, 1]):
//   s = 4.09712 + 4.20863 A - sqrt(9.59217 + 41.6808 A + 17.7126 A^2)
// and alpha = (1 - s^2) / (1 - g s^2). For g other than 0, s is van de Hulst's similarity parameter, so a forward or
// backward scattering medium keeps the multiple-scattering albedo A.
#pragma once

#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "renderer/math.h"
#include "renderer/medium.h"

namespace tessera {

// The single-scattering albedo alpha whose semi-infinite medium of phase asymmetry g reflects A (both in [0, 1]).
double subsurface_single_scattering_albedo(double multiscatter_albedo, double g);

// The OpenPBR subsurface parameters of a material.
struct SubsurfaceParams {
  float weight = 0;                     // subsurface_weight: the share of the dielectric base that is the volume
  Rgb color{0.8f, 0.8f, 0.8f};          // subsurface_color, the multiple-scattering albedo
  float radius = 1;                     // subsurface_radius: the mean free path, scene units
  Rgb radius_scale{1.0f, 0.5f, 0.25f};  // subsurface_radius_scale: the mean free path's scale per channel
  float anisotropy = 0;                 // subsurface_scatter_anisotropy, g
};

// The interior medium of the parameters (the mapping above).
std::shared_ptr<const Medium> subsurface_medium(const SubsurfaceParams& p);

// Reads the subsurface_* keys of a material's JSON object (each optional, OpenPBR's defaults); subsurface_weight only
// when `with_weight`. Throws SceneError naming the field for a value out of range: a colour outside [0, 1], a radius
// or scale that is not positive, |g| >= 1, anything not finite.
SubsurfaceParams read_subsurface(const nlohmann::json& j, const std::string& pointer, bool with_weight);

}  // namespace tessera
