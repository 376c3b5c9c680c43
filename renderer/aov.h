// Render passes (arbitrary output variables, AOVs): images a job asks for beside the beauty, for compositing and for
// the denoiser and adaptive sampling that read them. A job names them in render.aovs; each is a layer of the film
// (film.h), summed in fixed point like the beauty, so that passes merge across threads, passes, resumes and work
// units to the same bits, or worked out from the film's own statistics when it is resolved.
//
// Where each pass's value comes from (the definitions of Blender Cycles' passes, and for the denoising features those
// of Intel Open Image Denoise: the first surface that is not a perfect mirror or glass, seen through them):
//   albedo, normal        the first surface whose BSDF is not wholly a delta lobe, seen through perfect mirrors, glass
//                         and index-matched boundaries: its albedo (Bsdf::albedo_hint) times the throughput of the
//                         delta bounces before it, its shading normal (world space, facing the ray); averaged over
//                         the pixel's samples, 0 for a sample that escapes first. A scattering event in a medium before
//                         any such surface gives the throughput as albedo and a zero normal.
//   depth                 the distance along the camera ray (scene units) to the first drawn surface (index-matched
//                         boundaries are not drawn), averaged over the samples that hit one; infinite where none did
//   uv, roughness         the first drawn surface's first texture coordinates and perceptual roughness
//                         (Bsdf::roughness_hint), averaged over the pixel's samples (0 where a sample escapes)
//   position, object_id,  the first drawn surface's world position, object number + 1 and material number + 1
//   material_id           (SurfaceInteraction::object, material_index; 0 where the ray escapes), from the pixel's
//                         sample 0 alone, as Cycles writes its id passes: an average across an edge would be no
//                         object's id. A film without sample 0 (a part of a split job before its merge) has none.
//   sample_count          the samples the pixel received
//   variance              per channel, the variance of the pixel's mean, from the sum of its samples' squares:
//                         (E[L^2] - E[L]^2) / (n - 1), infinite below 2 samples
//   crypto_object,        Cryptomatte (cryptomatte.h): the ids of the names of the first drawn surface's object and
//   crypto_material       material, counted over the pixel's samples (samples that escape count for no id), ranked
//                         with their coverage; stored as the layers CryptoObject00 … 02 and CryptoMaterial00 … 02
// and the light passes, which split the beauty by where its light came from, as Cycles' do (Blender manual, "Render
// Passes"): emission (emitters seen from the camera, directly or across index-matched boundaries), background (the
// environment seen so), and by the first bounce of the path: diffuse, glossy and transmission (the lobe class that
// scattered it, Bsdf::lobe_colors) or volume (a scattering event in a medium), each _direct (light arriving at that
// first bounce: its light sample and the emitter its scattered ray hits) and _indirect (everything after). The
// surface classes also have a _color, the first bounce's lobe colour; their _direct and _indirect are summed whole
// and divided by the pixel's _color when resolved (0 where the colour is), so that per pixel
//   beauty = emission + background + volume_direct + volume_indirect + sum over X of (X_direct + X_indirect) * X_color
// to float rounding.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "renderer/cryptomatte.h"
#include "renderer/film.h"
#include "renderer/math.h"

namespace tessera {

enum class AovSource : uint8_t {
  kShading,      // albedo, normal: the first surface not wholly delta, seen through delta bounces
  kSurface,      // uv, roughness: the first drawn surface, averaged
  kDistance,     // depth: averaged over the samples that hit
  kFirstSample,  // position, ids: the pixel's sample 0
  kSampleCount,  // the film's per-pixel sample counts (no layer of its own)
  kSquares,      // variance: the beauty's squares
  kLight,        // the light passes: summed per sample; a _direct or _indirect pass divided by its _color when resolved
  kCryptomatte,  // crypto_object, crypto_material: the first drawn surface's ids, counted
};

struct AovInfo {
  std::string_view name;
  int channels = 1;
  std::array<std::string_view, 3> channel_names;  // as the EXR stores them, <name>.<channel>
  LayerKind kind = LayerKind::kRadiance;          // of its film layer
  AovSource source = AovSource::kSurface;
  bool always_float = false;     // stored as 32-bit float whatever the EXR precision
  std::string_view divisor;      // kLight: the pass this one is divided by when resolved (X_color), or empty
  std::string_view crypto_type;  // kCryptomatte: the type name its EXR layers and metadata carry ("CryptoObject")
};

// The EXR channel names of a pass: <name>.<channel> (albedo.R), a Cryptomatte pass's the specification's
// (CryptoObject00.R …).
std::vector<std::string> aov_channel_names(const AovInfo& aov);

// Every pass, in the order images list them.
const std::vector<AovInfo>& aov_table();
// The pass named `name`, or null.
const AovInfo* find_aov(std::string_view name);
// What is wrong with a pass name that find_aov does not know: unknown pass "albdo" (did you mean "albedo"?) ...
std::string unknown_aov_message(std::string_view name);

// The film layers the passes `aovs` (names find_aov knows) accumulate into, in the table's order. Any light pass
// brings the layers of all of them: they are recorded together, and a _direct or _indirect pass needs its _color.
std::vector<const AovInfo*> aov_layers(const std::vector<std::string>& aovs);
// Adds those layers to `film`; `ids` (needed when a Cryptomatte pass is among them) gives their manifests.
void add_aov_layers(Film& film, const std::vector<std::string>& aovs, const cryptomatte::Ids* ids = nullptr);
// The most bytes a width x height film with the passes `aovs` holds: 56 a pixel for the beauty (three 128-bit sums,
// its squared luminance and its sample count), 16 a channel for each layer, 4 more for a distance layer's hit counts,
// and for an id layer 168 (a vector of up to Film::kMaxIdsPerPixel (id, count) pairs, and the allocator's overhead).
uint64_t film_bytes(int width, int height, const std::vector<std::string>& aovs);
// The passes a film holds (in the table's order): those with a layer in it, and sample_count when `sample_count`.
std::vector<std::string> aovs_of(const Film& film, bool sample_count);

// What a camera sample's light adds to the light passes (kLight), filled in by the integrators. The classes are
// Bsdf's lobe classes: 0 diffuse, 1 glossy, 2 transmission.
struct LightPassSample {
  Rgb emission, background, volume_direct, volume_indirect;
  Rgb direct[3], indirect[3], color[3];
};

// What a camera sample found for the passes, filled in by the integrators.
struct SurfaceFeatures {
  bool surface = false;  // the camera ray reached a drawn surface; the fields up to `shaded` hold
  float depth = 0;
  Vec3 position;
  Vec2 uv;
  float roughness = 0;
  uint32_t object = 0;
  uint32_t material = 0;
  bool shaded = false;  // albedo and normal were found
  Rgb albedo;
  Vec3 normal;
};

// Adds a sample's passes to the layers the film has (found by name once, when made): each pass only where the
// caller's thread owns the pixel, as Film::add_sample.
class AovWriter {
 public:
  // `ids`: the scene's Cryptomatte ids, which a film with a Cryptomatte pass needs (std::invalid_argument without).
  explicit AovWriter(const Film& film, const cryptomatte::Ids* ids = nullptr);
  // Whether the film has a layer that SurfaceFeatures feed (the integrator records them only then).
  bool wants_features() const { return wants_features_; }
  // Whether the film has the light passes' layers (LightPassSample).
  bool wants_light() const { return light_[0] >= 0; }
  // Adds a sample's light passes to pixel (x, y); `shared`: while other threads may add to the same pixel (splats).
  void add_light(Film& film, int x, int y, const LightPassSample& l, bool shared = false) const;
  // Adds sample `sample_index` of pixel (x, y): its features and its beauty value `l` (for the variance's squares).
  void add(Film& film, int x, int y, uint32_t sample_index, const SurfaceFeatures& f, const Rgb& l) const;
  bool empty() const { return !wants_features_ && squares_ < 0 && !wants_light(); }

 private:
  int albedo_ = -1, normal_ = -1, depth_ = -1, uv_ = -1, roughness_ = -1, position_ = -1, object_ = -1, material_ = -1,
      squares_ = -1, crypto_object_ = -1, crypto_material_ = -1;
  const cryptomatte::Ids* ids_ = nullptr;
  bool wants_features_ = false;
  // The light passes' layers, in LightPassSample's order: emission, background, volume_direct, volume_indirect, then
  // the direct of diffuse, glossy and transmission, their indirect, their color.
  int light_[13];
};

// A resolved pass (`values`, aov.channels per pixel) as linear RGB to look at on a display (to_display, display.h):
// albedo as it is; roughness and sample_count grey (the count over the image's largest); normal as (n + 1) / 2;
// depth and position stretched over the image's finite range (near bright; escaped rays black); uv as the fractions
// of u and v; ids as a colour per id (0, nothing, black); variance as the standard deviation of the luminance over the
// image's largest (white where it is unknown); Cryptomatte as each rank's id colour weighted by its coverage.
std::vector<float> aov_look(const AovInfo& aov, const std::vector<float>& values);

// The pass `aov` of the film, its channels interleaved per pixel, row-major. Throws std::invalid_argument when the
// film lacks the pass's layer.
std::vector<float> resolve_aov(const Film& film, const AovInfo& aov);

}  // namespace tessera
