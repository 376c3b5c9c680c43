// A render's checkpoint: the film after a pass, so a job interrupted by a crash or a stop resumes where it was and,
// sampling being deterministic, ends with the bits an uninterrupted render gives. A work unit's film is its last
// checkpoint. The file is the film codec's (renderer/film_codec.h), its fingerprint the hash of the job's render
// settings: a checkpoint of another render is refused.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "renderer/byte_fields.h"
#include "renderer/film.h"
#include "renderer/render_settings.h"

namespace tessera::server {

struct Checkpoint {
  Film film;
  uint32_t passes = 0;
  double elapsed_s = 0;
};

// The checkpoint of `film` rendered with `settings` (its sample range and the job's budget are recorded).
std::string encode_checkpoint(const Film& film, uint32_t passes, double elapsed_s, uint64_t settings_hash,
                              const RenderSettings& settings);
// The checkpoint of `film` as samples 0 … of a job of unknown budget.
std::string encode_checkpoint(const Film& film, uint32_t passes, double elapsed_s, uint64_t settings_hash);
// Nothing when the bytes are not a complete, intact checkpoint of a `width`×`height` render with these settings.
std::optional<Checkpoint> decode_checkpoint(std::string_view bytes, int width, int height, uint64_t settings_hash);

using tessera::fnv1a64;  // renderer/byte_fields.h: settings are fingerprinted with the hash checkpoints use

}  // namespace tessera::server
