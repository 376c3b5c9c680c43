// The film: per-pixel sums of samples in named layers (each pixel's estimate of the measurement equation, Dutré, Bala
// & Bekaert, Advanced Global Illumination, 2nd ed., §2.8, with a box pixel filter), plus what the noise estimate and
// per-pixel sampling need.
//
// Sums are kept in 128-bit fixed point (units of 2^-40). Integer addition is associative, so a pixel's sum does not
// depend on the order its samples were added in: films of disjoint sample ranges merge into exactly the image of one
// render of all samples, whatever the threads, tiles, passes or resumes, for every layer. Each sample is clamped to
// ±2^80 (far beyond any physical value, and finite); a sum stays within its 127 bits for up to 2^32 samples of
// magnitude below 2^55.
//
// Layer 0 is always the beauty, "radiance": 3 channels (R, G, B) clamped to [0, 2^80] as radiance is non-negative,
// with a float sum of squared luminance per pixel for the noise estimate. Further layers are added by name, each of
// one kind:
//   - kRadiance: non-negative values (albedo, emission), clamped as the beauty is;
//   - kSigned:   values of either sign (normal, position, uv), clamped symmetrically to [-2^80, 2^80];
//   - kDistance: one channel of distances (depth): only finite non-negative values are summed, and a per-pixel count
//                of them is kept beside the sum, so a ray that escapes (infinite distance) is counted out rather than
//                putting an infinity in a sum; the pixel's mean is over its hits, infinite where there were none.
//   - kIds:      ids (Cryptomatte's, cryptomatte.h) counted per pixel: each pixel holds the ids its samples found and
//                how many samples found each, in the order of the ids. Counts are integers, so merging two films adds
//                them and the result is the same in any order. A pixel keeps at most kMaxIdsPerPixel ids; a sample of
//                a further id is left out of the counts (the pixel's sample count still has it). The layer also
//                holds the manifest, the names its ids stand for. It resolves to `channels` / 2 ranks of (id,
//                coverage): the ids by falling count (ties by rising id), each with its count over the pixel's
//                samples (Cryptomatte's ranking pixel filter with a box filter, Friedman and Jones 2015).
// Every pixel also has its own sample count (adaptive sampling, adaptive.h, gives pixels different counts), and each
// pixel's mean is over its own count. The film's samples() is how far the render's sample schedule has gone: every
// pixel still sampling has that many, a pixel that stopped early fewer.
#pragma once

#include <cmath>
#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "renderer/large_alloc.h"
#include "renderer/math.h"

namespace tessera {

using FixedSum = __int128;
// A layer's sums: large arrays, in huge pages where the kernel gives them (large_alloc.h).
using FixedSums = std::vector<FixedSum, LargeAllocator<FixedSum>>;
inline constexpr double kFixedScale = 0x1p40;

enum class LayerKind : uint32_t { kRadiance = 0, kSigned = 1, kDistance = 2, kIds = 3 };

// One id of a pixel of a kIds layer and the samples that found it.
struct IdCount {
  uint32_t id = 0;
  uint32_t count = 0;
  bool operator==(const IdCount&) const = default;
};

// One named layer's per-pixel statistics.
struct FilmLayer {
  std::string name;
  int channels = 0;
  LayerKind kind = LayerKind::kRadiance;
  FixedSums sums;              // `channels` per pixel, interleaved, row-major from the top left
  std::vector<uint32_t> hits;  // kDistance: per pixel, the samples whose distance was finite; empty otherwise
  std::vector<std::vector<IdCount>> ids;     // kIds: per pixel, its ids in rising order (no sums)
  std::map<std::string, uint32_t> manifest;  // kIds: the name each id stands for, by name
};

class Film {
 public:
  static constexpr const char* kBeauty = "radiance";
  static constexpr int kMaxLayers = 64;
  static constexpr int kMaxChannels = 16;
  static constexpr size_t kMaxNameLength = 31;
  static constexpr size_t kMaxIdsPerPixel = 16;

  Film() = default;
  Film(int width, int height);

  int width() const { return width_; }
  int height() const { return height_; }
  size_t pixel_count() const { return static_cast<size_t>(width_) * static_cast<size_t>(height_); }
  // How far the sample schedule has gone: the samples every pixel of the region received, for a film whose pixels
  // all advance together (pass by pass); with adaptive sampling, the count of the pixels still sampling.
  uint32_t samples() const { return samples_; }
  // Sets the film's count and every pixel's to `n`.
  void set_samples(uint32_t n);
  // Sets the film's count to `n`, the count of each pixel of the rectangle (x, y, w, h) to `n` and of every other
  // pixel to 0: a film of a region of the image.
  void set_samples(uint32_t n, int x, int y, int w, int h);
  // Adds `n` to the film's count and to the count of each pixel `active` marks (1; the whole image's size, row-major):
  // a pass of adaptive sampling.
  void advance_samples(uint32_t n, const std::vector<uint8_t>& active);
  // Sets the film's count to `n`, every pixel's left as it is: a schedule that ends early, every pixel having
  // stopped; a merge of parts of one sample range over different regions (Film::merge added their counts).
  void set_schedule_samples(uint32_t n) { samples_ = n; }
  uint32_t pixel_samples(int x, int y) const { return pixel_samples_[index(x, y)]; }
  const std::vector<uint32_t>& pixel_sample_counts() const { return pixel_samples_; }
  std::vector<uint32_t>& pixel_sample_counts() { return pixel_samples_; }

  // Layers. add_layer returns the new layer's index (the beauty's is 0), and throws std::invalid_argument for a name
  // already there, empty, longer than kMaxNameLength or not printable ASCII, a channel count outside
  // [1, kMaxChannels] (a distance layer has one), or more than kMaxLayers layers. Look a layer up by name once, and
  // add samples by its index: no lookup per sample.
  int add_layer(std::string name, int channels, LayerKind kind);
  // The index of the layer named `name`, or -1.
  int layer(std::string_view name) const;
  int layer_count() const { return 1 + static_cast<int>(extra_.size()); }
  const FilmLayer& layer_at(int i) const { return i == 0 ? beauty_ : extra_[static_cast<size_t>(i - 1)]; }
  FilmLayer& layer_at(int i) { return i == 0 ? beauty_ : extra_[static_cast<size_t>(i - 1)]; }
  // Whether `other` has the same size and the same layers (names, channels, kinds, in order).
  bool same_layout(const Film& other) const;

  void add_sample(int x, int y, const Rgb& radiance) {
    size_t i = index(x, y);
    beauty_.sums[3 * i] += to_fixed(radiance.x);
    beauty_.sums[3 * i + 1] += to_fixed(radiance.y);
    beauty_.sums[3 * i + 2] += to_fixed(radiance.z);
    float l = luminance(radiance);
    sum_lum2_[i] += l * l;
  }
  // Adds `value` to the radiance sums of pixel (x, y) while other threads may add to the same pixel: a light path's
  // contribution lands wherever it projects (Veach 1997, 10.3.4), not in a pixel a thread owns. Each 128-bit sum is
  // added as two 64-bit atomic additions, the carry of the low word into the high one: integer additions in any
  // order and interleaving end in the same bits, so a film of splats is the same whatever the threads. Splats do not
  // count as samples and leave the squared-luminance sums (the noise estimate's) alone.
  void splat(int x, int y, const Rgb& value) {
    size_t i = index(x, y);
    for (int c = 0; c < 3; ++c) atomic_add(beauty_.sums[3 * i + static_cast<size_t>(c)], to_fixed(value[c]));
  }
  // add_sample on a film that other threads splat onto at the same time: the radiance sums added as splat() adds
  // them; the squared luminance as add_sample does (only the calling thread adds samples to this pixel).
  void add_sample_shared(int x, int y, const Rgb& radiance) {
    splat(x, y, radiance);
    float l = luminance(radiance);
    sum_lum2_[index(x, y)] += l * l;
  }
  // Adds one sample of layer `layer` (an index from add_layer or layer()) to pixel (x, y): `values` holds the layer's
  // channels. On the beauty (layer 0) it is add_sample.
  void add_layer_sample(int layer, int x, int y, const float* values);
  // Counts one sample of id `id` in pixel (x, y) of the kIds layer `layer`, from the thread that owns the pixel.
  void add_id_sample(int layer, int x, int y, uint32_t id);
  // add_layer_sample while other threads may add to the same pixel (the sums and hit counts added atomically, as
  // splat() adds; on the beauty, as splat(): no squared luminance).
  void add_layer_sample_shared(int layer, int x, int y, const float* values);

  // Mean radiance of a pixel, over its own samples (mean_divisor).
  Rgb pixel(int x, int y) const {
    size_t i = index(x, y);
    const uint32_t n = mean_divisor(i);
    double inv = n > 0 ? 1.0 / (kFixedScale * n) : 0.0;
    return Rgb(static_cast<float>(static_cast<double>(beauty_.sums[3 * i]) * inv),
               static_cast<float>(static_cast<double>(beauty_.sums[3 * i + 1]) * inv),
               static_cast<float>(static_cast<double>(beauty_.sums[3 * i + 2]) * inv));
  }
  // Adds the samples of `other` (same layout, a disjoint sample range): exact for every layer's sums, hit counts and
  // id counts (a kIds pixel keeps its kMaxIdsPerPixel ids of most samples, ties to the lower id) and for the
  // per-pixel counts; manifests are joined. Throws std::invalid_argument for another layout.
  void merge(const Film& other);
  // Mean radiance of every pixel over its own samples (mean_divisor), RGB interleaved, row-major from the top-left.
  std::vector<float> resolve() const;
  // Mean of every pixel of a layer, its channels interleaved: over the pixel's own sample count (0 for a pixel
  // without samples); a distance layer's over the pixel's hits (infinite for a pixel without any); an id layer's
  // ranks of (id as the float of its bits, coverage), (0, 0) for ranks the pixel has no id for.
  std::vector<float> resolve_layer(int layer) const;
  // resolve_layer of the layer named `name`; throws std::invalid_argument when there is none.
  std::vector<float> resolve_layer(std::string_view name) const;
  // Estimated relative standard error of the image mean luminance: sqrt(mean pixel variance of the mean) divided by
  // the mean luminance, each pixel's variance over its own samples (mean_divisor).
  double relative_error() const;
  // What pixel i's beauty sums are divided by: its own sample count; the film's samples() for a pixel without samples
  // of its own (outside the region rendered), which only splats of light paths reach.
  uint32_t mean_divisor(size_t i) const { return pixel_samples_[i] > 0 ? pixel_samples_[i] : samples_; }

  // Raw state of the beauty: 3 fixed-point sums per pixel (RGB), and per-pixel sums of squared luminance (float,
  // only for the noise estimate). The film codec (renderer/film_codec.h) reads and writes every layer's.
  const FixedSums& sums() const { return beauty_.sums; }
  const std::vector<float>& sums_lum2() const { return sum_lum2_; }
  FixedSums& sums() { return beauty_.sums; }
  std::vector<float>& sums_lum2() { return sum_lum2_; }

  static FixedSum to_fixed(float v) {
    double d = static_cast<double>(v);
    if (!(d > 0)) return 0;
    // Below 2^23 the scaled value fits in 63 bits: one hardware conversion, the same truncation as the 128-bit one
    // (which is a library call, and was a measurable share of the render loop).
    if (d < 0x1p23) return static_cast<int64_t>(d * kFixedScale);
    if (d > 0x1p80) d = 0x1p80;
    return static_cast<FixedSum>(d * kFixedScale);
  }
  // to_fixed for values of either sign: clamped to [-2^80, 2^80], truncated toward zero, NaN as 0.
  static FixedSum to_fixed_signed(float v) {
    double d = static_cast<double>(v);
    if (!(d == d)) return 0;
    if (d > -0x1p23 && d < 0x1p23) return static_cast<int64_t>(d * kFixedScale);
    d = std::fmin(std::fmax(d, -0x1p80), 0x1p80);
    return static_cast<FixedSum>(d * kFixedScale);
  }

 private:
  static void atomic_add(FixedSum& sum, FixedSum value) {
    // Little-endian: the low word first. The two words' additions with the carry are the 128-bit two's complement
    // addition, exact for values of either sign while the sum stays within 128 bits.
    static_assert(sizeof(FixedSum) == 2 * sizeof(uint64_t));
    uint64_t* words = reinterpret_cast<uint64_t*>(&sum);
    const uint64_t lo = static_cast<uint64_t>(value), hi = static_cast<uint64_t>(value >> 64);
    const uint64_t before = __atomic_fetch_add(&words[0], lo, __ATOMIC_RELAXED);
    const uint64_t carry = before + lo < before ? 1 : 0;
    if (hi + carry != 0) __atomic_fetch_add(&words[1], hi + carry, __ATOMIC_RELAXED);
  }
  size_t index(int x, int y) const {
    return static_cast<size_t>(y) * static_cast<size_t>(width_) + static_cast<size_t>(x);
  }
  int width_ = 0, height_ = 0;
  uint32_t samples_ = 0;
  FilmLayer beauty_;                     // layer 0, kept apart so add_sample reaches its sums in one step
  std::vector<float> sum_lum2_;          // the beauty's, per pixel
  std::vector<FilmLayer> extra_;         // layers 1 …
  std::vector<uint32_t> pixel_samples_;  // per pixel
};

}  // namespace tessera
