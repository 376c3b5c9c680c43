// Partial films (.tfilm): what `tessera render --samples START:COUNT -o part.tfilm` writes and `tessera merge` reads.
//
// A partial film is the state of a Film (every layer, the per-pixel sample counts) after rendering sample indices
// [first_sample, first_sample + sample_count) of a job, optionally for a pixel region only (zero outside it), in the
// film codec's file (renderer/film_codec.h, which documents the layout and the older versions still read). The
// command line leaves `passes` and `elapsed_s` 0, so the file's bytes depend on its samples alone: a merge and one
// render of the same samples write the same sums.
#pragma once

#include <string>
#include <string_view>

#include "renderer/film_codec.h"

namespace tessera::cli {

struct PartialFilm : tessera::FilmFile {
  std::string path;  // where it was read from, for messages
};

std::string encode_film(const PartialFilm& p);
// The partial film in `bytes`, read from `path` (named in messages, and kept in the result); fatal (a Failure, exit
// code 1) when the bytes are not one.
PartialFilm decode_film(std::string_view bytes, const std::string& path);

}  // namespace tessera::cli
