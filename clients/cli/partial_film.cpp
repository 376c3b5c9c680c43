#include "clients/cli/partial_film.h"

#include <cstring>

#include "clients/cli/cli_common.h"
#include "renderer/byte_fields.h"

namespace tessera::cli {

namespace {

constexpr char kFilmMagic[8] = {'T', 'S', 'R', 'F', 'I', 'L', 'M', '\n'};
constexpr uint32_t kFilmVersion = 2;
// The header of each version: version 2 adds the job's budget (and a reserved word) to version 1's.
constexpr size_t header_size(uint32_t version) {
  return version == 1 ? 64 : 72;
}

}  // namespace

std::string encode_film(const PartialFilm& p) {
  static_assert(sizeof(tessera::FixedSum) == 16);  // the layout of partial_film.h
  std::string out;
  out.reserve(header_size(kFilmVersion) + tessera::Film::state_size(p.width, p.height));
  out.append(kFilmMagic, 8);
  put_field<uint32_t>(out, kFilmVersion);
  put_field<int32_t>(out, p.width);
  put_field<int32_t>(out, p.height);
  put_field<uint32_t>(out, p.first_sample);
  put_field<uint32_t>(out, p.sample_count);
  put_field<int32_t>(out, p.region.x);
  put_field<int32_t>(out, p.region.y);
  put_field<int32_t>(out, p.region.width);
  put_field<int32_t>(out, p.region.height);
  put_field<uint32_t>(out, p.exr_half ? 1u : 0u);
  put_field<float>(out, p.display.exposure_ev);
  put_field<uint32_t>(out, p.display.tonemap == tessera::ToneMap::kAces ? 1u : 0u);
  put_field<uint64_t>(out, p.fingerprint);
  put_field<uint32_t>(out, p.job_spp);
  put_field<uint32_t>(out, 0);
  p.film.append_state(out);
  return out;
}

PartialFilm decode_film(std::string_view in, const std::string& path) {
  if (in.size() < header_size(1) || std::memcmp(in.data(), kFilmMagic, 8) != 0)
    fatal(path + " is not a tessera partial film (.tfilm)");
  const uint32_t version = get_field<uint32_t>(in, 8);
  if (version < 1 || version > kFilmVersion)
    fatal(path + ": partial film version " + std::to_string(version) + " (this tessera reads versions 1 and 2)");
  const size_t header = header_size(version);
  if (in.size() < header) fatal(path + ": truncated header");
  PartialFilm p;
  p.path = path;
  p.width = get_field<int32_t>(in, 12);
  p.height = get_field<int32_t>(in, 16);
  p.first_sample = get_field<uint32_t>(in, 20);
  p.sample_count = get_field<uint32_t>(in, 24);
  p.region = {get_field<int32_t>(in, 28), get_field<int32_t>(in, 32), get_field<int32_t>(in, 36),
              get_field<int32_t>(in, 40)};
  p.exr_half = (get_field<uint32_t>(in, 44) & 1u) != 0;
  p.display.exposure_ev = get_field<float>(in, 48);
  p.display.tonemap = get_field<uint32_t>(in, 52) == 1 ? tessera::ToneMap::kAces : tessera::ToneMap::kClamp;
  p.fingerprint = get_field<uint64_t>(in, 56);
  p.job_spp = version >= 2 ? get_field<uint32_t>(in, 64) : 0;
  if (p.width < 1 || p.height < 1 || p.width > 65536 || p.height > 65536) fatal(path + ": bad image size");
  const auto& r = p.region;
  // The far edges are compared as differences: x + width overflows an int for a region near 2^31 (the header is
  // whatever bytes the file holds).
  if (r.x < 0 || r.y < 0 || r.width < 1 || r.height < 1 || r.width > p.width - r.x || r.height > p.height - r.y)
    fatal(path + ": region outside the image");
  if (p.sample_count > UINT32_MAX - p.first_sample) fatal(path + ": sample range past 2^32");
  if (p.job_spp != 0 && p.first_sample + p.sample_count > p.job_spp)
    fatal(path + ": samples " + std::to_string(p.first_sample) + ".." +
          std::to_string(p.first_sample + p.sample_count) + " outside the job's budget of " +
          std::to_string(p.job_spp));
  if (in.size() != header + tessera::Film::state_size(p.width, p.height))
    fatal(path + ": truncated or oversized (" + std::to_string(in.size()) + " bytes for " + std::to_string(p.width) +
          "x" + std::to_string(p.height) + ")");
  p.film = tessera::Film(p.width, p.height);
  p.film.read_state(in.substr(header));  // the size is checked above
  p.film.set_samples(p.sample_count);
  return p;
}

}  // namespace tessera::cli
