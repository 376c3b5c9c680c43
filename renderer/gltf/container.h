// The binary glTF container (.glb; glTF 2.0 specification, section 4.4 "GLB File Format Specification"), read the
// same way wherever a .glb arrives: the daemon's upload check and the loader.
#pragma once

#include <string>
#include <string_view>
#include <variant>

namespace tessera {

struct GlbChunks {
  std::string_view json;  // the first chunk, which must be JSON
  std::string_view bin;   // the BIN chunk when the second chunk is one; empty otherwise
};

// Whether `bytes` start with the .glb magic ("glTF"); anything else is read as glTF JSON.
bool is_glb(std::string_view bytes);

// The chunks of a .glb: a 12-byte header (magic, version 2, the total length, which must be the file's), then chunks
// of an 8-byte header (length, type) and their data, each within the file, the first JSON. Or, when the container is
// malformed, why (without the file's name).
std::variant<GlbChunks, std::string> parse_glb(std::string_view bytes);

// A .glb of a JSON chunk holding `json` (padded with spaces) and, unless `bin` is empty, a BIN chunk holding `bin`
// (padded with zeros).
std::string make_glb(std::string_view json, std::string_view bin);

}  // namespace tessera
