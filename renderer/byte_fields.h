// The fields of the film files' binary headers (render checkpoints, server/jobs/checkpoint.h; partial films, .tfilm,
// clients/cli/partial_film.h) and the hash that checks them and fingerprints settings.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

namespace tessera {

// Appends `v` as its bytes in this machine's order (the files are read back where they are written: a checkpoint by
// the daemon that wrote it or one sharing its data volume, a partial film by the same build).
template <typename T>
void put_field(std::string& out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(b, sizeof(T));
}

// The field of type T at `offset` of `in` (the caller has checked that it lies within).
template <typename T>
T get_field(std::string_view in, size_t offset) {
  T v;
  std::memcpy(&v, in.data() + offset, sizeof(T));
  return v;
}

// The 64-bit FNV-1a hash (Fowler, Noll and Vo; its parameters as in IETF draft-eastlake-fnv) of `bytes`, continued
// from `h`, so that several pieces hash as their concatenation.
inline uint64_t fnv1a64(std::string_view bytes, uint64_t h = 0xcbf29ce484222325ull) {
  for (unsigned char c : bytes) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  return h;
}

}  // namespace tessera
