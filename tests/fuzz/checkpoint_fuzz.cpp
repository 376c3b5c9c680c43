// Fuzz target: a render checkpoint as the daemon reads one back to resume a job (server/jobs/checkpoint.h
// decode_checkpoint, the film codec of renderer/film_codec.h in any version it reads), for a 3x2 render with the
// settings hash kSettingsHash (the seeds are checkpoints of such a render; libFuzzer's comparison tracing finds the
// checksum a mutated payload needs). A checkpoint that decodes must encode to one that decodes to the same film, sample
// count, passes and time.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

#include "server/jobs/checkpoint.h"

namespace {

constexpr int kWidth = 3, kHeight = 2;
constexpr uint64_t kSettingsHash = 0x7465737365726121ull;

// A checkpoint's normal form: its film (every layer, the per-pixel counts), passes and time as the codec writes them.
std::string normal(const tessera::server::Checkpoint& c) {
  return tessera::server::encode_checkpoint(c.film, c.passes, c.elapsed_s, kSettingsHash);
}

bool same(const tessera::server::Checkpoint& a, const tessera::server::Checkpoint& b) {
  return normal(a) == normal(b) && a.film.samples() == b.film.samples();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera::server;
  const auto decoded =
      decode_checkpoint(std::string_view(reinterpret_cast<const char*>(data), size), kWidth, kHeight, kSettingsHash);
  if (!decoded) return 0;
  const std::string again = encode_checkpoint(decoded->film, decoded->passes, decoded->elapsed_s, kSettingsHash);
  const auto redecoded = decode_checkpoint(again, kWidth, kHeight, kSettingsHash);
  if (!redecoded || !same(*decoded, *redecoded)) std::abort();
  return 0;
}
