// The film codec: one binary file of a Film with every layer and the per-pixel sample counts, and what is needed to
// resume, merge or check it. Render checkpoints (server/jobs/checkpoint.h), the server's work-unit films and the
// command line's partial films (.tfilm, clients/cli/partial_film.h) are all this file.
//
// Layout, versions 3 and 4 (all fields little-endian, as the machines we run on; offsets in bytes):
//
//   offset  size  field
//        0     8  magic "TSRFILM\n"
//        8     4  u32 version (3, or 4 with id layers)
//       12     4  i32 width            the full image, 1 … 65536
//       16     4  i32 height
//       20     4  u32 first_sample     the sample range's first index
//       24     4  u32 sample_count     samples every pixel of the region received (the film's samples())
//       28    16  i32 x, y, w, h       the region rendered (the whole image when not cropped)
//       44     4  u32 flags            bit 0: the job's EXR output is half precision; bit 1: the job asks for the
//                                      sample_count pass (aov.h; the other passes are layers); bits 2-3: the job's
//                                      denoiser (0 none, 1 regression: denoise.h); the others 0
//       48     4  f32 exposure_ev      the job's display settings, for PNG outputs of a merge
//       52     4  u32 tonemap          0 clamp, 1 ACES
//       56     8  u64 fingerprint      FNV-1a 64 of the settings the pixels depend on: films of other settings never
//                                      merge or resume
//       64     4  u32 job_spp          the job's sample budget, samples [0, job_spp) (0: unknown)
//       68     4  u32 passes           progressive passes rendered (0 where not recorded)
//       72     8  f64 elapsed_s        render time (0 where not recorded)
//       80     4  u32 layer_count      1 … 64
//       84     4  u32 reserved (0)
//       88     8  u64 checksum         FNV-1a 64 of bytes [0, 88) followed by every byte from 96 to the end
//       96  40·L  the layers: name (32 bytes, printable ASCII padded with NUL, at least one NUL), u32 channels
//                 (1 … 16), u32 kind (0 radiance, 1 signed, 2 distance, 3 ids); the first is "radiance", 3
//                 channels, kind 0
//   then, per layer in order, with N = width × height, row-major from the top left:
//            16·C·N  its sums, C channels per pixel interleaved: i128 fixed point in units of 2^-40 (none for ids)
//               4·N  the first layer only: f32 sums of squared luminance (the noise estimate's)
//               4·N  a distance layer only: u32 hit counts
//               4·N  an id layer only: u32 ids per pixel (0 … 16), then for every pixel in turn its ids as
//                    (u32 id, u32 count) pairs in rising id order, then the manifest: u32 names, and per name
//                    u32 id, u32 length (at most 4096) and its bytes, in the names' byte order
//   and last 4·N  u32 per-pixel sample counts.
// The file size is checked exactly against the header and the id layers' counts. A film with an id layer is version 4;
// one without is version 3, byte for byte the file it was before id layers existed.
//
// Older files still read, as a film of the radiance layer alone whose pixels all have sample_count samples (those
// outside the region none):
//   - checkpoints "TSRCKPT1" version 3 (checksum over header and payload) and 2 (over the payload only): a 48-byte
//     header, magic | version | width | height | samples | passes | reserved (u32 each) | elapsed_s f64 |
//     settings fingerprint u64, then the checksum u64 and the radiance state (3·N i128, N f32); the whole image,
//     first_sample 0, job_spp 0 (unknown);
//   - partial films "TSRFILM\n" version 2 (the version 3 header's first 68 bytes, a reserved u32, then the radiance
//     state) and 1 (the first 64 bytes alone: job_spp unknown), without a checksum.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "renderer/display.h"
#include "renderer/film.h"
#include "renderer/integrator.h"
#include "renderer/render_settings.h"

namespace tessera {

// The header fields.
struct FilmFileHeader {
  int width = 0, height = 0;
  uint32_t first_sample = 0, sample_count = 0;
  uint32_t job_spp = 0;  // the whole job's samples per pixel; 0 unknown
  PixelRegion region;    // {0, 0, width, height} for the whole image
  bool exr_half = true;
  bool sample_count_pass = false;      // the job asks for the sample_count pass
  Denoiser denoise = Denoiser::kNone;  // the job's denoiser, for the images of a merge
  DisplaySettings display;
  uint64_t fingerprint = 0;
  uint32_t passes = 0;
  double elapsed_s = 0;
};

struct FilmFile : FilmFileHeader {
  Film film;  // width × height, samples() == sample_count
};

// The file of `film` with the header fields of `h` (version 3). Throws std::invalid_argument when the film is not
// h.width × h.height.
std::string encode_film_file(const FilmFileHeader& h, const Film& film);
inline std::string encode_film_file(const FilmFile& f) {
  return encode_film_file(f, f.film);
}
// The film file in `bytes` (any version above), or nothing with the reason in `*why` (when given) if the bytes are
// not a complete, intact, consistent one.
std::optional<FilmFile> decode_film_file(std::string_view bytes, std::string* why = nullptr);

}  // namespace tessera
