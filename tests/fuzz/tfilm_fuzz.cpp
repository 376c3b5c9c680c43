// Fuzz target: a partial film (.tfilm) as `tessera merge` reads one (clients/cli/partial_film.h decode_film: the film
// codec of renderer/film_codec.h, every version it reads, layers and per-pixel counts included). Bytes that are not a
// partial film are fatal (cli::Failure, exit code 1); any other exception, a crash or a sanitizer
// report is a finding. A film that decodes must encode to one that decodes to the same film and fields.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

#include "clients/cli/cli_common.h"
#include "clients/cli/partial_film.h"

namespace {

bool same(const tessera::cli::PartialFilm& a, const tessera::cli::PartialFilm& b) {
  // The encoding of a decoded film is its normal form (flags and tone map codes read as what they mean).
  return tessera::cli::encode_film(a) == tessera::cli::encode_film(b) && a.film.samples() == b.film.samples();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera::cli;
  PartialFilm film;
  try {
    film = decode_film(std::string_view(reinterpret_cast<const char*>(data), size), "part.tfilm");
  } catch (const Failure&) {
    return 0;
  }
  if (!same(film, decode_film(encode_film(film), "again.tfilm"))) std::abort();  // a Failure here is a finding too
  return 0;
}
