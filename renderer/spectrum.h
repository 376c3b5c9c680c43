// Wavelengths in an RGB renderer: what dispersion (an index of refraction that varies with wavelength) needs.
//
// tessera transports RGB everywhere. A path that meets a dispersive interface carries one wavelength, drawn once per
// pixel sample from a density p(lambda) over the visible range, and its throughput takes the weight
// w(lambda) / p(lambda) once, at its first dispersive vertex; every dispersive BSDF along it refracts by its index at
// that wavelength. w = (w_r, w_g, w_b) are the colour matching functions of CIE 1931 taken to linear sRGB (the
// XYZ-to-sRGB matrix of IEC 61966-2-1), their negative lobes clamped to zero and each channel scaled to integrate to
// 1, so that the expected weight is exactly (1, 1, 1): a path whose light does not depend on the wavelength keeps its
// colour on average, white stays white, and only dispersion spreads colours. The estimate is that of a spectral
// renderer whose other materials and lights are grey per channel (the usual spectral sampling of an RGB renderer;
// Wilkie et al. 2014, "Hero Wavelength Spectral Sampling", discuss the one-wavelength estimator this is). Clamping the
// negative lobes makes the most saturated spectral colours slightly paler than sRGB could not show anyway.
//
// p(lambda) is the mean of the three weights, so w_c / p <= 3: the colour noise is bounded. The weights are tabulated
// in 1 nm bins over [kMinNm, kMaxNm] and constant within a bin, which makes the expected weight (1, 1, 1) to rounding.
#pragma once

#include "renderer/math.h"

namespace tessera {

namespace spectrum {

constexpr float kMinNm = 380, kMaxNm = 780;

// CIE 1931 2-degree colour matching functions at `lambda_nm`, by the multi-lobe piecewise Gaussian fit of Wyman,
// Sloan & Shirley, "Simple Analytic Approximations to the CIE XYZ Color Matching Functions", JCGT 2(2), 2013.
Vec3 cie_xyz(float lambda_nm);

// Linear sRGB (D65) of a CIE XYZ colour (IEC 61966-2-1), computed in double precision.
Rgb xyz_to_linear_srgb(double x, double y, double z);

// One wavelength for a path: the wavelength and the weight w(lambda) / p(lambda) its throughput takes.
struct WavelengthSample {
  float lambda_nm = 0;
  Rgb weight{1, 1, 1};
};

// The wavelength for a uniform number u in [0, 1), by inverting the tabulated distribution of p(lambda).
WavelengthSample sample_wavelength(float u);

// The weight w(lambda) of each channel at `lambda_nm` and the density p(lambda) (per nm), as sample_wavelength draws.
Rgb channel_weight(float lambda_nm);
float wavelength_pdf(float lambda_nm);

// The index of refraction at `lambda_nm` of a material of index `ior` at the Fraunhofer d line (587.6 nm) and
// dispersion 20 / V_d (V_d its Abbe number), by the two-term Cauchy equation as glTF's KHR_materials_dispersion
// defines it: n = max(ior + (ior - 1) dispersion / 20 (523655 / lambda^2 - 1.5168), 1).
float dispersive_ior(float ior, float dispersion, float lambda_nm);

}  // namespace spectrum

}  // namespace tessera
