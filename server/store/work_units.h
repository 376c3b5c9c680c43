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
// adaptive image is then the same bits on one node and on a cluster.
//
// A frame range (render.frames of more than one frame) is split by frames instead, on every store: each unit is
// `render.frames.chunk` consecutive frames of the range (the last one fewer), each frame rendered whole at the job's
// spp, so that a frame is the still at its time whatever node renders it; its samples in the store are spp times its
// frames, which the job's progress sums. A frame is never split into sample ranges. Samples are spread evenly, the
// first units taking one more when the division leaves a remainder.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "renderer/render_settings.h"

namespace tessera::server {

inline constexpr uint64_t kDefaultUnitPixelSamples = 20'000'000;

// How many sample-range units a job of these render settings is split into; 1 when `unit_pixel_samples` is 0 (never
// split) or the job is small, or stops on time or noise, or samples adaptively, or is a frame range.
int unit_count(const RenderSettings& settings, uint64_t unit_pixel_samples);

// A frame range job: render.frames of more than one frame (a range of one frame is the still at its time).
bool renders_frames(const RenderSettings& settings);
// The units of a frame range: its frames in chunks of render.frames.chunk.
int frame_unit_count(const RenderSettings& settings);
// The frame numbers of unit `unit` of a frame range, in order.
std::vector<int64_t> unit_frames(const RenderSettings& settings, int unit);
// A job's units as a store creates them (JobRecord::units): a frame range's chunks, else its sample ranges when the
// store splits jobs (`unit_pixel_samples` above 0), else 1.
int job_units(const RenderSettings& settings, uint64_t unit_pixel_samples);
// The pixel samples per pixel of the job's whole budget: spp, times the frames of a range.
uint32_t job_samples_total(const RenderSettings& settings);

struct SampleRange {
  uint32_t first = 0;
  uint32_t count = 0;
};
// The sample ranges of `units` units of `spp` samples: contiguous, in order, covering [0, spp).
std::vector<SampleRange> split_samples(uint32_t spp, int units);
// The sample ranges of a job's `units` units, as its store records them: a frame range's units each {0, spp x its
// frames}; a still's split_samples() of its spp (`samples_total`). `settings_text` is the record's.
std::vector<SampleRange> unit_sample_ranges(const std::string& settings_text, uint32_t samples_total, int units);

}  // namespace tessera::server
