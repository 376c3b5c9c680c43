// Cryptomatte: ID mattes a compositor picks by name (Friedman and Jones 2015, "Fully Automatic ID Mattes with Support
// for Motion Blur and Transparency", SIGGRAPH poster; the Cryptomatte specification 1.1.0, Psyop 2017).
//
// A name (an object's, a material's) is hashed with the 32-bit MurmurHash3 (Appleby 2011; Debian's libmurmurhash),
// and the hash becomes the bits of a 32-bit float whose exponent is clamped to [1, 254], so that no id is a zero, a
// denormal, an infinity or a NaN ("uint32_to_float32"). The film counts, per pixel, the samples that found each id
// (film.h, LayerKind::kIds); the image holds the ids of the most samples, ranked, each with its coverage, as RGBA
// layers <type>00, <type>01, ...: R the id of rank 2k, G its coverage, B the id of rank 2k + 1, A its coverage. The
// EXR header names each type under a key of its own: cryptomatte/<key>/name, hash, conversion and manifest (a JSON
// object of name → the id's float bits in 8 hexadecimal digits).
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tessera::cryptomatte {

// The ranks an image holds of each type: the specification's suggested default of 6, three RGBA layers.
inline constexpr int kRanks = 6;
// The longest name an id is made of, in bytes: longer ones are cut (ids_of).
inline constexpr size_t kMaxNameBytes = 256;

// MurmurHash3_x86_32 of the name's bytes, seed 0.
uint32_t hash(std::string_view name);
// The id of a hash: the bits of the float the image stores (the exponent clamped to [1, 254]).
uint32_t id_bits(uint32_t hash);
inline uint32_t id_of(std::string_view name) {
  return id_bits(hash(name));
}
// The float of those bits.
float id_float(uint32_t bits);

// The ids of a scene's objects and materials, by their numbers (SurfaceInteraction::object, material_index), and the
// manifests that name them; names longer than kMaxNameBytes are cut to that.
struct Ids {
  std::vector<uint32_t> object, material;
  std::map<std::string, uint32_t> object_manifest, material_manifest;
};
Ids ids_of(const std::vector<std::string>& object_names, const std::vector<std::string>& material_names);

// The EXR header attributes of the type `type_name` ("CryptoObject") whose ids `manifest` names, as (name, value)
// pairs: cryptomatte/<key>/name, hash, conversion, manifest; <key> the first 7 hexadecimal digits of the type name's
// hash, as the specification suggests.
std::vector<std::pair<std::string, std::string>> exr_metadata(std::string_view type_name,
                                                              const std::map<std::string, uint32_t>& manifest);
// The channel names of the type's `ranks` ranks: <type>00.R, <type>00.G, <type>00.B, <type>00.A, <type>01.R, ...
std::vector<std::string> channel_names(std::string_view type_name, int ranks);

}  // namespace tessera::cryptomatte
