// A render's checkpoint: the film after a pass, so a job interrupted by a crash or a stop resumes where it was and,
// sampling being deterministic, ends with the bits an uninterrupted render gives.
//
// Layout (little-endian, as the machines we run on): a 48-byte header
//   magic "TSRCKPT1" (8) | version u32 | width u32 | height u32 | samples u32 | passes u32 | reserved u32 |
//   elapsed_s f64 | settings_hash u64 (of the job's render settings: a checkpoint of another render is refused)
// then checksum u64 (FNV-1a 64 of the header and the payload; version 2, still read, covered the payload only), then
// the payload: the film's state (Film::append_state: its RGB sums,
// 3·w·h 128-bit fixed point, and its luminance square sums, w·h f32).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "renderer/byte_fields.h"
#include "renderer/film.h"

namespace tessera::server {

struct Checkpoint {
  Film film;
  uint32_t passes = 0;
  double elapsed_s = 0;
};

std::string encode_checkpoint(const Film& film, uint32_t passes, double elapsed_s, uint64_t settings_hash);
// Nothing when the bytes are not a complete, intact checkpoint of a `width`×`height` render with these settings.
std::optional<Checkpoint> decode_checkpoint(std::string_view bytes, int width, int height, uint64_t settings_hash);

using tessera::fnv1a64;  // renderer/byte_fields.h: settings are fingerprinted with the hash checkpoints use

}  // namespace tessera::server
