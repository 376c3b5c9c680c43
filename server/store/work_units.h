// Work units: a job's samples per pixel split into ranges that different nodes render at once. Sampling is
// deterministic in (seed, pixel, sample index) and the film's sums are fixed point (film.h), so the films of disjoint
// sample ranges merge into exactly the image one render of all of them gives, whatever the order or the node.
//
// The rule: a unit is about `unit_pixel_samples` pixel samples (width x height x samples), so that it takes tens of
// seconds on one thread (2 x 10^7 by default: the path-traced Cornell box runs at 3-6 x 10^5 pixel samples per second
// per thread on the 2-vCPU machine we measured, bench/cluster_scaling.sh; nodes of many threads want it larger), and a
// job is split into ceil(width x height x spp / unit_pixel_samples) units,
// at most one per sample. A job that stops on a time limit or a noise target, or samples adaptively
// (render.adaptive_threshold), is one unit: its stop is a property of the whole render, not of a sample range, and an
// adaptive image is then the same bits on one node and on a cluster. A frame range is one unit too (rendered frame by
// frame). Samples are spread evenly, the first units taking one more when the
// division leaves a remainder.
#pragma once

#include <cstdint>
#include <vector>

#include "renderer/render_settings.h"

namespace tessera::server {

inline constexpr uint64_t kDefaultUnitPixelSamples = 20'000'000;

// How many units a job of these render settings is split into; 1 when `unit_pixel_samples` is 0 (never split) or the
// job is small, or stops on time or noise.
int unit_count(const RenderSettings& settings, uint64_t unit_pixel_samples);

struct SampleRange {
  uint32_t first = 0;
  uint32_t count = 0;
};
// The sample ranges of `units` units of `spp` samples: contiguous, in order, covering [0, spp).
std::vector<SampleRange> split_samples(uint32_t spp, int units);

}  // namespace tessera::server
