#include "server/checkpoint.h"

#include "renderer/film_codec.h"

namespace tessera::server {

std::string encode_checkpoint(const Film& film, uint32_t passes, double elapsed_s, uint64_t settings_hash,
                              const RenderSettings& settings) {
  FilmFileHeader f;
  f.width = film.width();
  f.height = film.height();
  f.first_sample = settings.first_sample;
  f.sample_count = film.samples();
  // A default RenderSettings (spp 0) knows no budget: recorded as unknown.
  f.job_spp = settings.spp > 0 ? settings.budget() : 0;
  f.region = {0, 0, film.width(), film.height()};
  f.exr_half = settings.exr_half;
  f.display = settings.display;
  f.fingerprint = settings_hash;
  f.passes = passes;
  f.elapsed_s = elapsed_s;
  return encode_film_file(f, film);
}

std::optional<Checkpoint> decode_checkpoint(std::string_view bytes, int width, int height, uint64_t settings_hash) {
  std::optional<FilmFile> f = decode_film_file(bytes);
  if (!f || f->width != width || f->height != height || f->fingerprint != settings_hash) return std::nullopt;
  return Checkpoint{std::move(f->film), f->passes, f->elapsed_s};
}

}  // namespace tessera::server
