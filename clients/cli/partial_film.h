// Partial films (.tfilm): what `tessera render --samples START:COUNT -o part.tfilm` writes and `tessera merge` reads.
//
// A partial film is the raw state of a Film after rendering sample indices [first_sample, first_sample + count)
// of a job, optionally for a pixel region only. All fields little-endian:
//
//   offset  size  field
//        0     8  magic "TSRFILM\n"
//        8     4  u32 version (2; version 1 files, without the budget, are read as of an unknown budget)
//       12     4  i32 width            the full image
//       16     4  i32 height
//       20     4  u32 first_sample     the range's first sample index
//       24     4  u32 sample_count     samples every pixel of the region received (a time limit may cut a range)
//       28    16  i32 x, y, w, h       the region rendered (the whole image when not cropped)
//       44     4  u32 flags            bit 0: the job's EXR output is half precision
//       48     4  f32 exposure_ev      the job's display settings, for PNG outputs of a merge
//       52     4  u32 tonemap          0 clamp, 1 ACES
//       56     8  u64 fingerprint      FNV-1a of the scene and the settings the pixels depend on (not the sample
//                                      range, region, time limit or display): parts of different jobs never merge
//       64     4  u32 job_spp          the job's sample budget: samples [0, job_spp) of every pixel make its image
//                                      (0: unknown, as in a version 1 file)
//       68     4  u32 reserved (0)
//       72  52·N  the film's state (Film::append_state; zero outside the region): 3 × i128 per pixel (R, G, B),
//                 row-major from the top left, fixed point in units of 2^-40, then an f32 per pixel, its sum of
//                 squared luminance (for the noise estimate only)
//
// with N = width × height. The file size is checked exactly.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "renderer/film.h"
#include "renderer/image_io.h"
#include "renderer/session.h"

namespace tessera::cli {

struct PartialFilm {
  int width = 0, height = 0;
  uint32_t first_sample = 0, sample_count = 0;
  uint32_t job_spp = 0;  // the whole job's samples per pixel; 0 in a version 1 file (unknown)
  tessera::RenderSettings::Region region;
  bool exr_half = true;
  tessera::DisplaySettings display;
  uint64_t fingerprint = 0;
  tessera::Film film;
  std::string path;  // where it was read from, for messages
};

std::string encode_film(const PartialFilm& p);
// The partial film in `bytes`, read from `path` (named in messages, and kept in the result); fatal (a Failure, exit
// code 1) when the bytes are not one.
PartialFilm decode_film(std::string_view bytes, const std::string& path);

}  // namespace tessera::cli
