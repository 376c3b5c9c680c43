#include "server/jobs/checkpoint.h"

#include "renderer/film_codec.h"

namespace tessera::server {

namespace {

// `settings` null: a range from 0 of an unknown budget.
std::string encode(const Film& film, uint32_t passes, double elapsed_s, uint64_t settings_hash,
                   const RenderSettings* settings) {
  FilmFileHeader f;
  f.width = film.width();
  f.height = film.height();
  f.first_sample = settings ? settings->first_sample : 0;
  f.sample_count = film.samples();
  f.job_spp = settings ? settings->budget() : 0;
  f.region = {0, 0, film.width(), film.height()};
  if (settings) {
    f.exr_half = settings->exr_half;
    f.display = settings->display;
  }
  f.fingerprint = settings_hash;
  f.passes = passes;
  f.elapsed_s = elapsed_s;
  return encode_film_file(f, film);
}

}  // namespace

std::string encode_checkpoint(const Film& film, uint32_t passes, double elapsed_s, uint64_t settings_hash,
                              const RenderSettings& settings) {
  return encode(film, passes, elapsed_s, settings_hash, &settings);
}

std::string encode_checkpoint(const Film& film, uint32_t passes, double elapsed_s, uint64_t settings_hash) {
  return encode(film, passes, elapsed_s, settings_hash, nullptr);
}

std::optional<Checkpoint> decode_checkpoint(std::string_view bytes, int width, int height, uint64_t settings_hash) {
  std::optional<FilmFile> f = decode_film_file(bytes);
  if (!f || f->width != width || f->height != height || f->fingerprint != settings_hash) return std::nullopt;
  return Checkpoint{std::move(f->film), f->passes, f->elapsed_s};
}

}  // namespace tessera::server
