// Fuzz target: a render checkpoint as the daemon reads one back to resume a job (server/checkpoint.h
// decode_checkpoint), for a 3x2 render with the settings hash kSettingsHash (the seeds are checkpoints of such a
// render; libFuzzer's comparison tracing finds the checksum a mutated payload needs). A checkpoint that decodes must
// encode to one that decodes to the same film, sample count, passes and time.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

#include "server/checkpoint.h"

namespace {

constexpr int kWidth = 3, kHeight = 2;
constexpr uint64_t kSettingsHash = 0x7465737365726121ull;

std::string state(const tessera::Film& film) {
  std::string out;
  film.append_state(out);
  return out;
}

bool same(const tessera::server::Checkpoint& a, const tessera::server::Checkpoint& b) {
  return state(a.film) == state(b.film) && a.film.samples() == b.film.samples() && a.passes == b.passes &&
         std::memcmp(&a.elapsed_s, &b.elapsed_s, sizeof(double)) == 0;
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
