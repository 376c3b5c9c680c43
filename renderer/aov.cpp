#include "renderer/aov.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <utility>

#include "proto/did_you_mean.h"

namespace tessera {

namespace {

// The squares of the variance pass live in a layer of this name: the pass's own name, its resolved values being
// derived from the layer and the beauty.
constexpr std::string_view kVariance = "variance";

}  // namespace

const std::vector<AovInfo>& aov_table() {
  using K = LayerKind;
  using S = AovSource;
  static const std::vector<AovInfo> table = {
      {"albedo", 3, {"R", "G", "B"}, K::kRadiance, S::kShading, false, {}, {}},
      {"normal", 3, {"X", "Y", "Z"}, K::kSigned, S::kShading, false, {}, {}},
      {"depth", 1, {"Z"}, K::kDistance, S::kDistance, true, {}, {}},
      {"position", 3, {"X", "Y", "Z"}, K::kSigned, S::kFirstSample, true, {}, {}},
      {"uv", 2, {"U", "V"}, K::kSigned, S::kSurface, false, {}, {}},
      {"roughness", 1, {"X"}, K::kRadiance, S::kSurface, false, {}, {}},
      {"object_id", 1, {"X"}, K::kSigned, S::kFirstSample, true, {}, {}},
      {"material_id", 1, {"X"}, K::kSigned, S::kFirstSample, true, {}, {}},
      {"sample_count", 1, {"X"}, K::kRadiance, S::kSampleCount, true, {}, {}},
      {kVariance, 3, {"R", "G", "B"}, K::kRadiance, S::kSquares, true, {}, {}},
      {"emission", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, {}, {}},
      {"background", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, {}, {}},
      {"volume_direct", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, {}, {}},
      {"volume_indirect", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, {}, {}},
      {"diffuse_direct", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, "diffuse_color", {}},
      {"diffuse_indirect", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, "diffuse_color", {}},
      {"diffuse_color", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, {}, {}},
      {"glossy_direct", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, "glossy_color", {}},
      {"glossy_indirect", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, "glossy_color", {}},
      {"glossy_color", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, {}, {}},
      {"transmission_direct", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, "transmission_color", {}},
      {"transmission_indirect", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, "transmission_color", {}},
      {"transmission_color", 3, {"R", "G", "B"}, K::kRadiance, S::kLight, false, {}, {}},
      {"crypto_object", 2 * cryptomatte::kRanks, {}, K::kIds, S::kCryptomatte, true, {}, "CryptoObject"},
      {"crypto_material", 2 * cryptomatte::kRanks, {}, K::kIds, S::kCryptomatte, true, {}, "CryptoMaterial"},
  };
  return table;
}

std::vector<std::string> aov_channel_names(const AovInfo& aov) {
  if (aov.source == AovSource::kCryptomatte) return cryptomatte::channel_names(aov.crypto_type, aov.channels / 2);
  std::vector<std::string> names;
  for (int c = 0; c < aov.channels; ++c)
    names.push_back(std::string(aov.name) + "." + std::string(aov.channel_names[static_cast<size_t>(c)]));
  return names;
}

const AovInfo* find_aov(std::string_view name) {
  for (const AovInfo& a : aov_table())
    if (a.name == name) return &a;
  return nullptr;
}

std::string unknown_aov_message(std::string_view name) {
  std::vector<std::string_view> names;
  for (const AovInfo& a : aov_table()) names.push_back(a.name);
  std::string message =
      "unknown pass \"" + std::string(name) + "\"" + proto::did_you_mean(name, names) + "; the passes are";
  for (std::string_view n : names) message.append(" ").append(n);
  return message;
}

std::vector<const AovInfo*> aov_layers(const std::vector<std::string>& aovs) {
  auto asked = [&](const AovInfo& a) { return std::find(aovs.begin(), aovs.end(), a.name) != aovs.end(); };
  bool light = false;
  for (const AovInfo& a : aov_table()) light = light || (a.source == AovSource::kLight && asked(a));
  std::vector<const AovInfo*> layers;
  for (const AovInfo& a : aov_table()) {
    if (a.source == AovSource::kSampleCount) continue;
    if (asked(a) || (light && a.source == AovSource::kLight)) layers.push_back(&a);
  }
  return layers;
}

void add_aov_layers(Film& film, const std::vector<std::string>& aovs, const cryptomatte::Ids* ids) {
  for (const AovInfo* a : aov_layers(aovs)) {
    const int layer = film.add_layer(std::string(a->name), a->channels, a->kind);
    if (a->source != AovSource::kCryptomatte) continue;
    if (!ids) throw std::invalid_argument("the pass " + std::string(a->name) + " needs the scene's Cryptomatte ids");
    film.layer_at(layer).manifest = a->crypto_type == "CryptoObject" ? ids->object_manifest : ids->material_manifest;
  }
}

namespace {

// An id layer's pixel at its largest: its vector, and the vector's block of 16 pairs with the allocator's own
// 16 bytes (glibc's malloc chunk header and alignment).
constexpr uint64_t kIdsPixelBytes = sizeof(std::vector<IdCount>) + Film::kMaxIdsPerPixel * sizeof(IdCount) + 16;

}  // namespace

uint64_t film_bytes(int width, int height, const std::vector<std::string>& aovs) {
  uint64_t per_pixel = 3 * sizeof(FixedSum) + sizeof(float) + sizeof(uint32_t);
  for (const AovInfo* a : aov_layers(aovs))
    per_pixel += a->kind == LayerKind::kIds ? kIdsPixelBytes
                                            : static_cast<uint64_t>(a->channels) * sizeof(FixedSum) +
                                                  (a->kind == LayerKind::kDistance ? 4 : 0);
  return per_pixel * static_cast<uint64_t>(width) * static_cast<uint64_t>(height);
}

std::vector<std::string> aovs_of(const Film& film, bool sample_count) {
  std::vector<std::string> aovs;
  for (const AovInfo& a : aov_table())
    if (a.source == AovSource::kSampleCount ? sample_count : film.layer(a.name) >= 0) aovs.emplace_back(a.name);
  // (A film with light passes holds all their layers, whichever of them the job asked for: a merge writes them all.)
  return aovs;
}

AovWriter::AovWriter(const Film& film, const cryptomatte::Ids* ids)
    : albedo_(film.layer("albedo")),
      normal_(film.layer("normal")),
      depth_(film.layer("depth")),
      uv_(film.layer("uv")),
      roughness_(film.layer("roughness")),
      position_(film.layer("position")),
      object_(film.layer("object_id")),
      material_(film.layer("material_id")),
      squares_(film.layer(kVariance)),
      crypto_object_(film.layer("crypto_object")),
      crypto_material_(film.layer("crypto_material")),
      ids_(ids) {
  if ((crypto_object_ >= 0 || crypto_material_ >= 0) && !ids_)
    throw std::invalid_argument("a film with Cryptomatte passes needs the scene's ids");
  for (int layer :
       {albedo_, normal_, depth_, uv_, roughness_, position_, object_, material_, crypto_object_, crypto_material_})
    wants_features_ = wants_features_ || layer >= 0;
  static constexpr std::string_view kLightLayers[13] = {
      "emission",      "background",          "volume_direct",     "volume_indirect", "diffuse_direct",
      "glossy_direct", "transmission_direct", "diffuse_indirect",  "glossy_indirect", "transmission_indirect",
      "diffuse_color", "glossy_color",        "transmission_color"};
  for (int i = 0; i < 13; ++i) light_[i] = film.layer(kLightLayers[i]);
  for (int i = 0; i < 13; ++i)
    if (light_[i] < 0) light_[0] = -1;  // all of them or none
}

void AovWriter::add_light(Film& film, int x, int y, const LightPassSample& l, bool shared) const {
  const Rgb* values[13] = {&l.emission,  &l.background, &l.volume_direct, &l.volume_indirect, &l.direct[0],
                           &l.direct[1], &l.direct[2],  &l.indirect[0],   &l.indirect[1],     &l.indirect[2],
                           &l.color[0],  &l.color[1],   &l.color[2]};
  for (int i = 0; i < 13; ++i) {
    // Most of a sample's light lands in a few passes: adding zero to the others would change no sum.
    if (is_black(*values[i])) continue;
    if (shared)
      film.add_layer_sample_shared(light_[i], x, y, &values[i]->x);
    else
      film.add_layer_sample(light_[i], x, y, &values[i]->x);
  }
}

void AovWriter::add(Film& film, int x, int y, uint32_t sample_index, const SurfaceFeatures& f, const Rgb& l) const {
  if (squares_ >= 0) {
    const float sq[3] = {l.x * l.x, l.y * l.y, l.z * l.z};
    film.add_layer_sample(squares_, x, y, sq);
  }
  if (!wants_features_) return;
  if (f.shaded) {
    if (albedo_ >= 0) film.add_layer_sample(albedo_, x, y, &f.albedo.x);
    if (normal_ >= 0) film.add_layer_sample(normal_, x, y, &f.normal.x);
  }
  if (!f.surface) {
    // Escaped: depth counts the sample out (an infinite distance is not summed); the first sample's ids are 0.
    if (depth_ >= 0) {
      const float inf = INFINITY;
      film.add_layer_sample(depth_, x, y, &inf);
    }
    return;
  }
  if (depth_ >= 0) film.add_layer_sample(depth_, x, y, &f.depth);
  if (uv_ >= 0) film.add_layer_sample(uv_, x, y, &f.uv.x);
  if (roughness_ >= 0) film.add_layer_sample(roughness_, x, y, &f.roughness);
  if (crypto_object_ >= 0 && f.object < ids_->object.size())
    film.add_id_sample(crypto_object_, x, y, ids_->object[f.object]);
  if (crypto_material_ >= 0 && f.material < ids_->material.size())
    film.add_id_sample(crypto_material_, x, y, ids_->material[f.material]);
  if (sample_index != 0) return;
  if (position_ >= 0) film.add_layer_sample(position_, x, y, &f.position.x);
  const float object = static_cast<float>(f.object) + 1, material = static_cast<float>(f.material) + 1;
  if (object_ >= 0) film.add_layer_sample(object_, x, y, &object);
  if (material_ >= 0) film.add_layer_sample(material_, x, y, &material);
}

namespace {

// The smallest and largest finite values of channel c of n-channel pixels; {0, 0} when none is finite.
std::pair<float, float> finite_range(const std::vector<float>& v, size_t n, size_t c) {
  float lo = INFINITY, hi = -INFINITY;
  for (size_t i = c; i < v.size(); i += n)
    if (std::isfinite(v[i])) lo = std::min(lo, v[i]), hi = std::max(hi, v[i]);
  return lo <= hi ? std::pair{lo, hi} : std::pair{0.0f, 0.0f};
}

float stretch(float v, std::pair<float, float> range) {
  if (!std::isfinite(v)) return 0;
  return range.second > range.first ? (v - range.first) / (range.second - range.first) : 1.0f;
}

// A colour of its own for each number: its bits mixed by MurmurHash3's 32-bit finaliser (Appleby 2011), three
// of its bytes as the channels, kept away from black.
Rgb bits_colour(uint32_t h) {
  h ^= h >> 16;
  h *= 0x85ebca6bu;
  h ^= h >> 13;
  h *= 0xc2b2ae35u;
  h ^= h >> 16;
  auto channel = [&](int shift) { return 0.15f + 0.85f * static_cast<float>((h >> shift) & 0xffu) / 255.0f; };
  return Rgb(channel(0), channel(8), channel(16));
}

// An id pass's colour (0, nothing, black).
Rgb id_colour(float id) {
  if (!(id > 0)) return Rgb(0);
  return bits_colour(static_cast<uint32_t>(id));
}

// The colour of a Cryptomatte id: of its float's bits.
Rgb crypto_colour(float id) {
  uint32_t bits;
  std::memcpy(&bits, &id, sizeof bits);
  return bits_colour(bits);
}

}  // namespace

std::vector<float> aov_look(const AovInfo& aov, const std::vector<float>& values) {
  const size_t n = static_cast<size_t>(aov.channels), pixels = values.size() / n;
  std::vector<float> rgb(3 * pixels, 0.0f);
  auto set = [&](size_t i, Rgb c) {
    rgb[3 * i] = c.x;
    rgb[3 * i + 1] = c.y;
    rgb[3 * i + 2] = c.z;
  };
  if (aov.name == "albedo" || aov.source == AovSource::kLight) return values;
  if (aov.name == "normal") {
    for (size_t i = 0; i < pixels; ++i)
      set(i, Rgb(values[3 * i] + 1, values[3 * i + 1] + 1, values[3 * i + 2] + 1) * 0.5f);
  } else if (aov.name == "depth") {
    const auto range = finite_range(values, 1, 0);
    for (size_t i = 0; i < pixels; ++i)
      set(i, Rgb(std::isfinite(values[i]) ? 1 - 0.9f * stretch(values[i], range) : 0));
  } else if (aov.name == "position") {
    const std::pair<float, float> ranges[3] = {finite_range(values, 3, 0), finite_range(values, 3, 1),
                                               finite_range(values, 3, 2)};
    for (size_t i = 0; i < pixels; ++i)
      set(i, Rgb(stretch(values[3 * i], ranges[0]), stretch(values[3 * i + 1], ranges[1]),
                 stretch(values[3 * i + 2], ranges[2])));
  } else if (aov.name == "uv") {
    for (size_t i = 0; i < pixels; ++i)
      set(i, Rgb(values[2 * i] - std::floor(values[2 * i]), values[2 * i + 1] - std::floor(values[2 * i + 1]), 0));
  } else if (aov.name == "object_id" || aov.name == "material_id") {
    for (size_t i = 0; i < pixels; ++i) set(i, id_colour(values[i]));
  } else if (aov.source == AovSource::kCryptomatte) {
    for (size_t i = 0; i < pixels; ++i) {
      Rgb c(0);
      for (size_t r = 0; r + 1 < n; r += 2)
        if (values[n * i + r + 1] > 0) c += crypto_colour(values[n * i + r]) * values[n * i + r + 1];
      set(i, c);
    }
  } else if (aov.name == "variance") {
    std::vector<float> deviation(pixels);
    for (size_t i = 0; i < pixels; ++i)
      deviation[i] = std::sqrt(std::max(0.0f, luminance(Rgb(values[3 * i], values[3 * i + 1], values[3 * i + 2]))));
    const float top = finite_range(deviation, 1, 0).second;
    for (size_t i = 0; i < pixels; ++i)
      set(i, Rgb(!std::isfinite(deviation[i]) ? 1.0f : top > 0 ? deviation[i] / top : 0.0f));
  } else {
    // One channel shown grey: roughness as it is, sample_count over the image's largest.
    const float top = aov.name == "sample_count" ? std::max(1.0f, finite_range(values, 1, 0).second) : 1.0f;
    for (size_t i = 0; i < pixels; ++i) set(i, Rgb(values[i * n] / top));
  }
  return rgb;
}

std::vector<float> resolve_aov(const Film& film, const AovInfo& aov) {
  const size_t n = film.pixel_count();
  if (aov.source == AovSource::kSampleCount) {
    std::vector<float> out(n);
    for (size_t i = 0; i < n; ++i) out[i] = static_cast<float>(film.pixel_sample_counts()[i]);
    return out;
  }
  const int index = film.layer(aov.name);
  if (index < 0) throw std::invalid_argument("the film has no layer for the pass " + std::string(aov.name));
  const FilmLayer& layer = film.layer_at(index);
  if (aov.source == AovSource::kFirstSample) {
    // One sample's value: the sum itself.
    std::vector<float> out(layer.sums.size());
    for (size_t i = 0; i < out.size(); ++i)
      out[i] = static_cast<float>(static_cast<double>(layer.sums[i]) / kFixedScale);
    return out;
  }
  if (aov.source == AovSource::kLight && !aov.divisor.empty()) {
    // The light's whole sum over its class's colour's, per channel (0 where the colour is 0).
    const int divisor = film.layer(aov.divisor);
    if (divisor < 0) throw std::invalid_argument("the film has no layer for the pass " + std::string(aov.divisor));
    const FixedSums& colors = film.layer_at(divisor).sums;
    std::vector<float> out(layer.sums.size());
    for (size_t i = 0; i < out.size(); ++i)
      out[i] = colors[i] > 0 ? static_cast<float>(static_cast<double>(layer.sums[i]) / static_cast<double>(colors[i]))
                             : 0.0f;
    return out;
  }
  if (aov.source != AovSource::kSquares) return film.resolve_layer(index);
  // The variance of the pixel's mean, per channel, from the sums of the samples and of their squares.
  std::vector<float> out(3 * n);
  const FixedSums& sums = film.sums();
  for (size_t i = 0; i < n; ++i) {
    const double count = film.pixel_sample_counts()[i];
    for (size_t c = 0; c < 3; ++c) {
      if (count < 2) {
        out[3 * i + c] = INFINITY;
        continue;
      }
      const double mean = static_cast<double>(sums[3 * i + c]) / (kFixedScale * count);
      const double mean_sq = static_cast<double>(layer.sums[3 * i + c]) / (kFixedScale * count);
      out[3 * i + c] = static_cast<float>(std::max(0.0, mean_sq - mean * mean) / (count - 1));
    }
  }
  return out;
}

}  // namespace tessera
