#include "server/checkpoint.h"

#include <cstring>

namespace tessera::server {

namespace {

constexpr char kMagic[8] = {'T', 'S', 'R', 'C', 'K', 'P', 'T', '1'};
// 2: 128-bit fixed-point radiance sums, the checksum over the payload; 3: the checksum over the header too (a flipped
// bit in the sample count would scale the image). Version 2 is still read: a job checkpointed by the daemon before
// an upgrade resumes.
constexpr uint32_t kVersion = 3;
constexpr uint32_t kPayloadChecksumVersion = 2;
constexpr size_t kHeaderBytes = 8 + 6 * 4 + 8 + 8;  // up to and including settings_hash
constexpr size_t kPrefixBytes = kHeaderBytes + 8;   // then the checksum

}  // namespace

std::string encode_checkpoint(const Film& film, uint32_t passes, double elapsed_s, uint64_t settings_hash) {
  std::string payload;
  payload.reserve(Film::state_size(film.width(), film.height()));
  film.append_state(payload);
  std::string out;
  out.reserve(kPrefixBytes + payload.size());
  out.append(kMagic, sizeof kMagic);
  put_field<uint32_t>(out, kVersion);
  put_field<uint32_t>(out, static_cast<uint32_t>(film.width()));
  put_field<uint32_t>(out, static_cast<uint32_t>(film.height()));
  put_field<uint32_t>(out, film.samples());
  put_field<uint32_t>(out, passes);
  put_field<uint32_t>(out, 0);
  put_field<double>(out, elapsed_s);
  put_field<uint64_t>(out, settings_hash);
  put_field<uint64_t>(out, fnv1a64(payload, fnv1a64(out)));
  out.append(payload);
  return out;
}

std::optional<Checkpoint> decode_checkpoint(std::string_view bytes, int width, int height, uint64_t settings_hash) {
  if (bytes.size() < kPrefixBytes || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0) return std::nullopt;
  const uint32_t version = get_field<uint32_t>(bytes, 8);
  if (version != kVersion && version != kPayloadChecksumVersion) return std::nullopt;
  const uint32_t w = get_field<uint32_t>(bytes, 12), h = get_field<uint32_t>(bytes, 16);
  if (static_cast<int>(w) != width || static_cast<int>(h) != height) return std::nullopt;
  if (get_field<uint64_t>(bytes, 40) != settings_hash) return std::nullopt;
  const std::string_view payload = bytes.substr(kPrefixBytes);
  if (payload.size() != Film::state_size(width, height)) return std::nullopt;
  const uint64_t checksum =
      version == kVersion ? fnv1a64(payload, fnv1a64(bytes.substr(0, kHeaderBytes))) : fnv1a64(payload);
  if (checksum != get_field<uint64_t>(bytes, kHeaderBytes)) return std::nullopt;
  Checkpoint c;
  c.film = Film(width, height);
  if (!c.film.read_state(payload)) return std::nullopt;
  c.film.set_samples(get_field<uint32_t>(bytes, 20));
  c.passes = get_field<uint32_t>(bytes, 24);
  c.elapsed_s = get_field<double>(bytes, 32);
  return c;
}

}  // namespace tessera::server
