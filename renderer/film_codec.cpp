#include "renderer/film_codec.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "renderer/byte_fields.h"

namespace tessera {

namespace {

constexpr char kFilmMagic[8] = {'T', 'S', 'R', 'F', 'I', 'L', 'M', '\n'};
constexpr char kCheckpointMagic[8] = {'T', 'S', 'R', 'C', 'K', 'P', 'T', '1'};
constexpr uint32_t kVersion = 3;  // a film without id layers; one with them is version 4
constexpr uint32_t kIdsVersion = 4;
constexpr uint32_t kMaxManifestName = 4096;  // bytes of one manifest name
constexpr size_t kChecksumAt = 88;           // version 3: the checksum's offset
constexpr size_t kHeaderBytes = 96;          // version 3: the fixed header
constexpr size_t kLayerEntryBytes = 40;      // version 3: one layer's name, channels, kind
constexpr size_t kNameBytes = 32;
constexpr int kMaxSide = 65536;
constexpr size_t kCheckpointHeaderBytes = 48;  // TSRCKPT1: up to and including the settings fingerprint
constexpr size_t kRadianceStateBytes = 3 * sizeof(FixedSum) + sizeof(float);  // per pixel, the older formats

static_assert(sizeof(FixedSum) == 16, "the file holds 128-bit sums");
static_assert(sizeof(IdCount) == 8, "the file holds an id and its count as two u32");

std::optional<FilmFile> refuse(std::string* why, std::string reason) {
  if (why) *why = std::move(reason);
  return std::nullopt;
}

// The checks every version's header passes: sizes, the region, the sample range.
bool valid_header(const FilmFile& f, std::string* why) {
  auto no = [&](std::string reason) {
    if (why) *why = std::move(reason);
    return false;
  };
  if (f.width < 1 || f.height < 1 || f.width > kMaxSide || f.height > kMaxSide) return no("bad image size");
  const PixelRegion& r = f.region;
  // The far edges are compared as differences: x + width overflows an int for a region near 2^31.
  if (r.x < 0 || r.y < 0 || r.width < 1 || r.height < 1 || r.width > f.width - r.x || r.height > f.height - r.y)
    return no("region outside the image");
  if (f.sample_count > UINT32_MAX - f.first_sample) return no("sample range past 2^32");
  if (f.job_spp != 0 && f.first_sample + f.sample_count > f.job_spp)
    return no("samples " + std::to_string(f.first_sample) + ".." + std::to_string(f.first_sample + f.sample_count) +
              " outside the job's budget of " + std::to_string(f.job_spp));
  if (!std::isfinite(f.elapsed_s) || f.elapsed_s < 0) return no("bad elapsed time");
  if (!std::isfinite(f.display.exposure_ev)) return no("bad exposure");
  return true;
}

size_t pixels_of(const FilmFile& f) {
  return static_cast<size_t>(f.width) * static_cast<size_t>(f.height);
}

// The older formats' payload: the radiance layer's sums and squared-luminance sums; every pixel of the region has
// sample_count samples.
void read_radiance_state(FilmFile& f, std::string_view payload) {
  f.film = Film(f.width, f.height);
  FixedSums& sums = f.film.sums();
  std::vector<float>& lum2 = f.film.sums_lum2();
  std::memcpy(sums.data(), payload.data(), sums.size() * sizeof(FixedSum));
  std::memcpy(lum2.data(), payload.data() + sums.size() * sizeof(FixedSum), lum2.size() * sizeof(float));
  f.film.set_samples(f.sample_count, f.region.x, f.region.y, f.region.width, f.region.height);
}

std::optional<FilmFile> decode_checkpoint_v2_v3(std::string_view in, std::string* why) {
  if (in.size() < kCheckpointHeaderBytes + 8) return refuse(why, "truncated header");
  const uint32_t version = get_field<uint32_t>(in, 8);
  if (version != 2 && version != 3)
    return refuse(why, "checkpoint version " + std::to_string(version) + " (versions 2 and 3 are read)");
  FilmFile f;
  const uint32_t w = get_field<uint32_t>(in, 12), h = get_field<uint32_t>(in, 16);
  if (w < 1 || h < 1 || w > kMaxSide || h > kMaxSide) return refuse(why, "bad image size");
  f.width = static_cast<int>(w);
  f.height = static_cast<int>(h);
  f.sample_count = get_field<uint32_t>(in, 20);
  f.passes = get_field<uint32_t>(in, 24);
  f.elapsed_s = get_field<double>(in, 32);
  f.fingerprint = get_field<uint64_t>(in, 40);
  f.region = {0, 0, f.width, f.height};
  f.exr_half = false;
  if (!valid_header(f, why)) return std::nullopt;
  const std::string_view payload = in.substr(kCheckpointHeaderBytes + 8);
  if (payload.size() != pixels_of(f) * kRadianceStateBytes) return refuse(why, "truncated or oversized");
  const uint64_t checksum =
      version == 3 ? fnv1a64(payload, fnv1a64(in.substr(0, kCheckpointHeaderBytes))) : fnv1a64(payload);
  if (checksum != get_field<uint64_t>(in, kCheckpointHeaderBytes)) return refuse(why, "checksum mismatch");
  read_radiance_state(f, payload);
  return f;
}

// The fields versions 1 to 3 of "TSRFILM\n" share, at offsets 12 to 64.
void read_common_fields(FilmFile& f, std::string_view in) {
  f.width = get_field<int32_t>(in, 12);
  f.height = get_field<int32_t>(in, 16);
  f.first_sample = get_field<uint32_t>(in, 20);
  f.sample_count = get_field<uint32_t>(in, 24);
  f.region = {get_field<int32_t>(in, 28), get_field<int32_t>(in, 32), get_field<int32_t>(in, 36),
              get_field<int32_t>(in, 40)};
  f.exr_half = (get_field<uint32_t>(in, 44) & 1u) != 0;
  f.sample_count_pass = (get_field<uint32_t>(in, 44) & 2u) != 0;
  f.denoise = ((get_field<uint32_t>(in, 44) >> 2) & 3u) == 1 ? Denoiser::kRegression : Denoiser::kNone;
  f.display.exposure_ev = get_field<float>(in, 48);
  f.display.tonemap = get_field<uint32_t>(in, 52) == 1 ? ToneMap::kAces : ToneMap::kClamp;
  f.fingerprint = get_field<uint64_t>(in, 56);
}

std::optional<FilmFile> decode_partial_v1_v2(std::string_view in, uint32_t version, std::string* why) {
  const size_t header = version == 1 ? 64 : 72;
  if (in.size() < header) return refuse(why, "truncated header");
  FilmFile f;
  read_common_fields(f, in);
  f.job_spp = version >= 2 ? get_field<uint32_t>(in, 64) : 0;
  if (!valid_header(f, why)) return std::nullopt;
  if (in.size() != header + pixels_of(f) * kRadianceStateBytes)
    return refuse(why, "truncated or oversized (" + std::to_string(in.size()) + " bytes for " +
                           std::to_string(f.width) + "x" + std::to_string(f.height) + ")");
  read_radiance_state(f, in.substr(header));
  return f;
}

// An id layer's variable part: per pixel its count of ids, then every pixel's (id, count) pairs, then the manifest
// (a count, then per name its id, its length and its bytes). `read` reads the next bytes or says there are none.
template <typename Read>
bool read_ids(FilmLayer& l, Read& read, std::string* why) {
  auto no = [&](std::string reason) {
    if (why) *why = "layer " + l.name + ": " + std::move(reason);
    return false;
  };
  std::vector<uint32_t> sizes(l.ids.size());
  if (!read(sizes.data(), sizes.size() * sizeof(uint32_t))) return no("truncated");
  for (size_t p = 0; p < sizes.size(); ++p) {
    if (sizes[p] > Film::kMaxIdsPerPixel)
      return no("a pixel with more than " + std::to_string(Film::kMaxIdsPerPixel) + " ids");
    l.ids[p].resize(sizes[p]);
    if (!read(l.ids[p].data(), sizes[p] * sizeof(IdCount))) return no("truncated");
    for (size_t k = 0; k < sizes[p]; ++k)
      if (l.ids[p][k].count == 0 || (k > 0 && l.ids[p][k].id <= l.ids[p][k - 1].id))
        return no("ids out of order or counted 0 times");
  }
  uint32_t names = 0;
  if (!read(&names, sizeof names)) return no("truncated manifest");
  for (uint32_t k = 0; k < names; ++k) {
    uint32_t id = 0, length = 0;
    if (!read(&id, sizeof id) || !read(&length, sizeof length) || length > kMaxManifestName)
      return no("truncated or bad manifest");
    std::string name(length, '\0');
    if (!read(name.data(), length)) return no("truncated manifest");
    l.manifest[std::move(name)] = id;
  }
  return true;
}

std::optional<FilmFile> decode_v3_v4(std::string_view in, uint32_t version, std::string* why) {
  if (in.size() < kHeaderBytes) return refuse(why, "truncated header");
  FilmFile f;
  read_common_fields(f, in);
  const uint32_t flags = get_field<uint32_t>(in, 44);
  if ((flags & ~15u) != 0 || ((flags >> 2) & 3u) > 1 || get_field<uint32_t>(in, 52) > 1 ||
      get_field<uint32_t>(in, 84) != 0)
    return refuse(why, "bad display fields or reserved bits");
  f.job_spp = get_field<uint32_t>(in, 64);
  f.passes = get_field<uint32_t>(in, 68);
  f.elapsed_s = get_field<double>(in, 72);
  if (!valid_header(f, why)) return std::nullopt;
  const uint32_t layers = get_field<uint32_t>(in, 80);
  if (layers < 1 || layers > static_cast<uint32_t>(Film::kMaxLayers)) return refuse(why, "bad layer count");
  const size_t table_end = kHeaderBytes + kLayerEntryBytes * layers;
  if (in.size() < table_end) return refuse(why, "truncated layer table");
  // The layers, checked as Film::add_layer checks them; the size the payload must have. N ≤ 2^32 and a pixel's
  // bytes ≤ 64 · (16 · 16 + 4) + 8, so the size fits 64 bits without overflow.
  const uint64_t n = pixels_of(f);
  uint64_t per_pixel = sizeof(uint32_t) + sizeof(float);  // the sample count, the beauty's squared luminance
  struct Entry {
    std::string name;
    int channels;
    LayerKind kind;
  };
  std::vector<Entry> entries;
  for (uint32_t i = 0; i < layers; ++i) {
    const std::string_view e = in.substr(kHeaderBytes + kLayerEntryBytes * i, kLayerEntryBytes);
    const std::string_view field = e.substr(0, kNameBytes);
    const size_t len = field.find('\0');
    if (len == std::string_view::npos || field.find_first_not_of('\0', len) != std::string_view::npos)
      return refuse(why, "bad layer name");
    const uint32_t channels = get_field<uint32_t>(e, kNameBytes), kind = get_field<uint32_t>(e, kNameBytes + 4);
    const uint32_t last_kind = static_cast<uint32_t>(version >= kIdsVersion ? LayerKind::kIds : LayerKind::kDistance);
    if (kind > last_kind || channels < 1 || channels > static_cast<uint32_t>(Film::kMaxChannels))
      return refuse(why, "bad layer " + std::to_string(i));
    entries.push_back({std::string(field.substr(0, len)), static_cast<int>(channels), static_cast<LayerKind>(kind)});
    if (kind == static_cast<uint32_t>(LayerKind::kIds))
      per_pixel += 4;  // the entry counts; the entries and the manifest follow, of their own sizes
    else
      per_pixel += 16ull * channels + (kind == static_cast<uint32_t>(LayerKind::kDistance) ? 4 : 0);
  }
  const bool has_ids =
      std::any_of(entries.begin(), entries.end(), [](const Entry& e) { return e.kind == LayerKind::kIds; });
  if (has_ids != (version == kIdsVersion))
    return refuse(why, "version " + std::to_string(version) + (has_ids ? " with" : " without") + " id layers");
  if (entries[0].name != Film::kBeauty || entries[0].channels != 3 || entries[0].kind != LayerKind::kRadiance)
    return refuse(why, "the first layer is not the beauty (radiance, 3 channels)");
  const uint64_t payload = in.size() - table_end;
  if (has_ids ? payload < n * per_pixel : payload != n * per_pixel)
    return refuse(why, "truncated or oversized (" + std::to_string(in.size()) + " bytes for " +
                           std::to_string(f.width) + "x" + std::to_string(f.height) + " and its layers)");
  if (get_field<uint64_t>(in, kChecksumAt) != fnv1a64(in.substr(kChecksumAt + 8), fnv1a64(in.substr(0, kChecksumAt))))
    return refuse(why, "checksum mismatch");
  f.film = Film(f.width, f.height);
  for (size_t i = 1; i < entries.size(); ++i) {
    try {
      f.film.add_layer(entries[i].name, entries[i].channels, entries[i].kind);
    } catch (const std::invalid_argument& e) {
      return refuse(why, e.what());
    }
  }
  size_t at = table_end;
  // Reads `bytes` more, false when the file has fewer left. (An empty array, an id layer's sums or a pixel without
  // ids, may have no storage at all: memcpy is not given its null pointer.)
  auto read = [&](void* to, size_t bytes) {
    if (bytes > in.size() - at) return false;
    if (bytes > 0) std::memcpy(to, in.data() + at, bytes);
    at += bytes;
    return true;
  };
  for (int i = 0; i < f.film.layer_count(); ++i) {
    FilmLayer& l = f.film.layer_at(i);
    if (!read(l.sums.data(), l.sums.size() * sizeof(FixedSum)) ||
        (i == 0 && !read(f.film.sums_lum2().data(), n * sizeof(float))) ||
        (l.kind == LayerKind::kDistance && !read(l.hits.data(), n * sizeof(uint32_t))))
      return refuse(why, "truncated");
    if (l.kind == LayerKind::kIds && !read_ids(l, read, why)) return std::nullopt;
  }
  f.film.set_samples(f.sample_count);
  if (!read(f.film.pixel_sample_counts().data(), n * sizeof(uint32_t))) return refuse(why, "truncated");
  if (at != in.size()) return refuse(why, "oversized");
  // An id layer's counts are samples of their pixel.
  for (int i = 0; i < f.film.layer_count(); ++i)
    for (size_t p = 0; p < f.film.layer_at(i).ids.size(); ++p) {
      uint64_t counted = 0;
      for (const IdCount& e : f.film.layer_at(i).ids[p]) counted += e.count;
      if (counted > f.film.pixel_sample_counts()[p])
        return refuse(why, "an id layer counts more samples than its pixel");
    }
  return f;
}

}  // namespace

std::string encode_film_file(const FilmFileHeader& f, const Film& film) {
  if (film.width() != f.width || film.height() != f.height)
    throw std::invalid_argument("the film is not the file's size");
  const size_t n = film.pixel_count();
  std::string out;
  out.append(kFilmMagic, sizeof kFilmMagic);
  bool has_ids = false;
  for (int i = 0; i < film.layer_count(); ++i) has_ids = has_ids || film.layer_at(i).kind == LayerKind::kIds;
  put_field<uint32_t>(out, has_ids ? kIdsVersion : kVersion);
  put_field<int32_t>(out, f.width);
  put_field<int32_t>(out, f.height);
  put_field<uint32_t>(out, f.first_sample);
  put_field<uint32_t>(out, f.sample_count);
  put_field<int32_t>(out, f.region.x);
  put_field<int32_t>(out, f.region.y);
  put_field<int32_t>(out, f.region.width);
  put_field<int32_t>(out, f.region.height);
  put_field<uint32_t>(
      out, (f.exr_half ? 1u : 0u) | (f.sample_count_pass ? 2u : 0u) | (f.denoise == Denoiser::kRegression ? 4u : 0u));
  put_field<float>(out, f.display.exposure_ev);
  put_field<uint32_t>(out, f.display.tonemap == ToneMap::kAces ? 1u : 0u);
  put_field<uint64_t>(out, f.fingerprint);
  put_field<uint32_t>(out, f.job_spp);
  put_field<uint32_t>(out, f.passes);
  put_field<double>(out, f.elapsed_s);
  put_field<uint32_t>(out, static_cast<uint32_t>(film.layer_count()));
  put_field<uint32_t>(out, 0);
  put_field<uint64_t>(out, 0);  // the checksum, below
  for (int i = 0; i < film.layer_count(); ++i) {
    const FilmLayer& l = film.layer_at(i);
    std::string name = l.name;
    name.resize(kNameBytes, '\0');
    out += name;
    put_field<uint32_t>(out, static_cast<uint32_t>(l.channels));
    put_field<uint32_t>(out, static_cast<uint32_t>(l.kind));
  }
  auto append = [&](const void* from, size_t bytes) {
    if (bytes > 0) out.append(static_cast<const char*>(from), bytes);
  };
  for (int i = 0; i < film.layer_count(); ++i) {
    const FilmLayer& l = film.layer_at(i);
    append(l.sums.data(), l.sums.size() * sizeof(FixedSum));
    if (i == 0) append(film.sums_lum2().data(), n * sizeof(float));
    if (l.kind == LayerKind::kDistance) append(l.hits.data(), n * sizeof(uint32_t));
    if (l.kind == LayerKind::kIds) {
      for (const std::vector<IdCount>& ids : l.ids) put_field<uint32_t>(out, static_cast<uint32_t>(ids.size()));
      for (const std::vector<IdCount>& ids : l.ids) append(ids.data(), ids.size() * sizeof(IdCount));
      put_field<uint32_t>(out, static_cast<uint32_t>(l.manifest.size()));
      for (const auto& [name, id] : l.manifest) {
        if (name.size() > kMaxManifestName)
          throw std::invalid_argument("a manifest name longer than " + std::to_string(kMaxManifestName) + " bytes");
        put_field<uint32_t>(out, id);
        put_field<uint32_t>(out, static_cast<uint32_t>(name.size()));
        out += name;
      }
    }
  }
  append(film.pixel_sample_counts().data(), n * sizeof(uint32_t));
  const uint64_t checksum =
      fnv1a64(std::string_view(out).substr(kChecksumAt + 8), fnv1a64(std::string_view(out).substr(0, kChecksumAt)));
  std::memcpy(out.data() + kChecksumAt, &checksum, sizeof checksum);
  return out;
}

std::optional<FilmFile> decode_film_file(std::string_view in, std::string* why) {
  if (in.size() >= 8 && std::memcmp(in.data(), kCheckpointMagic, 8) == 0) return decode_checkpoint_v2_v3(in, why);
  if (in.size() < 12 || std::memcmp(in.data(), kFilmMagic, 8) != 0) return refuse(why, "not a tessera film");
  const uint32_t version = get_field<uint32_t>(in, 8);
  if (version == 1 || version == 2) return decode_partial_v1_v2(in, version, why);
  if (version == kVersion || version == kIdsVersion) return decode_v3_v4(in, version, why);
  return refuse(why, "film version " + std::to_string(version) + " (this tessera reads versions 1 to 4)");
}

}  // namespace tessera
