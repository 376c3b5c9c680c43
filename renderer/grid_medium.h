// Heterogeneous media from OpenVDB grids (Museth 2013, "VDB: High-resolution sparse volumes with dynamic topology"):
// a float grid of densities, scaled by sigma_a and sigma_s per scene unit, read by trilinear interpolation. Free
// flights are sampled by delta tracking and transmittance estimated by ratio tracking against a majorant, a coarse
// grid of the largest extinctions cell by cell or the largest in the whole grid (Woodcock et al. 1965; Novák, Georgiev,
// Hanika and Jarosz 2018, "Monte Carlo methods for physically based volume rendering", §5; Pharr, Jakob and Humphreys,
// Physically Based Rendering, 4th ed., §14.2). OpenVDB stays inside grid_medium.cpp.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>

#include "renderer/medium.h"

namespace tessera {

// The most tentative collisions one tracking call (one transmittance estimate, one free flight) takes; past them the
// call ray-marches the rest of its stretch, a bounded quadrature of the density at 64 points: a transmittance
// estimate takes its product so far times the marched transmittance, and a free flight is sampled through the
// marched rest as through a homogeneous medium, in the coordinate of the density's integral. Delta and ratio
// tracking take about majorant x distance tentative collisions (Novák, Georgiev, Hanika and Jarosz 2018, §5; PBR 4th
// ed. §14.2), unbounded as density_scale grows, and where the steps 1 / majorant fall below a float's spacing the
// tracking does not advance at all. With a majorant mu tight over extinctions sigma_t, the transmittance left after N
// tentative collisions is about exp(-N sigma_t / mu): below exp(-10) for any majorant up to 6500 times the
// extinctions met (ratio tracking's Russian roulette has ended most such walks long before), so what a call does past
// the cap changes a negligible part of the estimate. Where the majorant is looser still (a long stretch of near-empty
// voxels under the majorant of a dense cell of 8 voxels, or under the global majorant) the call reaches the cap, and
// the marching's bias, small where the density varies little across a 64th of the rest, is the price of a call
// bounded to a few milliseconds; ending such a call as absorbed instead would darken every ray that crosses the empty
// edge of a dense cloud.
inline constexpr int kMaxTentativeCollisions = 1 << 16;

// The largest optical depth at the majorant across a grid's diagonal that a medium may have: 2^24, a float's
// significand. Beyond it the mean step 1 / majorant is below the spacing of float distances within the grid, so
// tracking cannot resolve the medium.
inline constexpr double kMaxMajorantOpticalDepth = 1 << 24;

struct GridMediumDesc {
  std::filesystem::path file;  // a .vdb file
  // The float grid of densities; empty: the grid named "density", else the file's first float grid.
  std::string grid_name;
  Rgb sigma_a{0}, sigma_s{0};  // per scene unit, at density 1
  float g = 0;                 // the Henyey–Greenstein asymmetry
  float density_scale = 1;     // multiplies every density
  // Where the grid's world space lies in the scene: scene = grid world * scale + translate.
  Vec3 translate{0};
  float scale = 1;
  uint64_t max_voxels = 64'000'000;  // active voxels (and tiles' voxels) a grid may hold
  // Track against a coarse grid of majorants (true) or the grid's one largest extinction (false): the same
  // estimates in expectation, at different costs.
  bool majorant_grid = true;
};

// Why a grid cannot be made a medium: `field` is the medium's key at fault ("grid", "grid_name").
class GridError : public std::runtime_error {
 public:
  GridError(std::string field, const std::string& message) : std::runtime_error(message), field(std::move(field)) {}
  std::string field;
};

// The medium of `desc`; throws GridError for a file that is not an OpenVDB file, a grid it does not hold, one that is
// not a float grid, one of more than max_voxels voxels or with negative densities, and ("density_scale") one whose
// majorant's optical depth across its diagonal exceeds kMaxMajorantOpticalDepth.
std::shared_ptr<const Medium> load_grid_medium(const GridMediumDesc& desc);

}  // namespace tessera
