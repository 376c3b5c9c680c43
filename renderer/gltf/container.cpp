#include "renderer/gltf/container.h"

#include <cstdint>
#include <cstring>

namespace tessera {

namespace {

constexpr uint32_t kJsonChunk = 0x4E4F534Au;  // "JSON"
constexpr uint32_t kBinChunk = 0x004E4942u;   // "BIN\0"

uint32_t u32(std::string_view b, size_t at) {
  uint32_t v;
  std::memcpy(&v, b.data() + at, 4);  // little-endian, as the container is and as the daemon's targets are
  return v;
}

}  // namespace

bool is_glb(std::string_view bytes) {
  return bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
}

std::variant<GlbChunks, std::string> parse_glb(std::string_view b) {
  if (b.size() < 20) return std::string("truncated: a .glb has a 12-byte header and a JSON chunk");
  if (!is_glb(b)) return std::string("not a binary glTF (wrong magic)");
  if (u32(b, 4) != 2) return "binary glTF container version " + std::to_string(u32(b, 4)) + ", expected 2";
  if (u32(b, 8) != b.size())
    return "the header declares " + std::to_string(u32(b, 8)) + " bytes but the file has " + std::to_string(b.size()) +
           " (truncated or padded)";
  GlbChunks chunks;
  size_t at = 12;
  for (int chunk = 0; at < b.size(); ++chunk) {
    if (b.size() - at < 8) return "truncated chunk header at byte " + std::to_string(at);
    const uint32_t length = u32(b, at), type = u32(b, at + 4);
    if (length > b.size() - at - 8)
      return "chunk " + std::to_string(chunk) + " declares " + std::to_string(length) +
             " bytes, beyond the end of the file";
    const std::string_view data = b.substr(at + 8, length);
    if (chunk == 0) {
      if (type != kJsonChunk) return std::string("the first chunk is not JSON");
      chunks.json = data;
    } else if (chunk == 1 && type == kBinChunk) {
      chunks.bin = data;
    }
    at += 8 + length;
  }
  return chunks;
}

std::string make_glb(std::string_view json, std::string_view bin) {
  auto padded = [](size_t n) { return (n + 3) & ~size_t{3}; };
  std::string out;
  auto u32 = [&](size_t v) {
    for (int i = 0; i < 4; ++i) out += static_cast<char>((v >> (8 * i)) & 0xff);
  };
  out += "glTF";
  u32(2);
  u32(12 + 8 + padded(json.size()) + (bin.empty() ? 0 : 8 + padded(bin.size())));
  u32(padded(json.size()));
  u32(kJsonChunk);
  out += json;
  out.append(padded(json.size()) - json.size(), ' ');
  if (!bin.empty()) {
    u32(padded(bin.size()));
    u32(kBinChunk);
    out += bin;
    out.append(padded(bin.size()) - bin.size(), '\0');
  }
  return out;
}

}  // namespace tessera
