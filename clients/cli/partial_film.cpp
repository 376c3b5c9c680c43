#include "clients/cli/partial_film.h"

#include "clients/cli/cli_common.h"

namespace tessera::cli {

std::string encode_film(const PartialFilm& p) {
  return tessera::encode_film_file(p);
}

PartialFilm decode_film(std::string_view in, const std::string& path) {
  std::string why;
  std::optional<tessera::FilmFile> f = tessera::decode_film_file(in, &why);
  if (!f) fatal(path + ": not a usable tessera partial film (.tfilm): " + why);
  PartialFilm p;
  static_cast<tessera::FilmFile&>(p) = std::move(*f);
  p.path = path;
  return p;
}

}  // namespace tessera::cli
