// Material parameters: a constant, or a texture evaluated at the shading point.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <type_traits>
#include <utility>
#include <vector>

#include "renderer/math.h"

namespace tessera {

// What a material sees of the surface it shades.
struct ShadingPoint {
  Vec3 p;       // world position
  Vec3 ng;      // geometric normal, world, as modelled (not flipped towards the viewer)
  Frame frame;  // shading frame, world; frame.n on the same side as ng
  Vec2 uv;      // first texture coordinate set
  Vec2 uv1;     // second set (glTF TEXCOORD_1), equal to uv where absent
  Rgb vertex_color{1, 1, 1};
  float tangent_sign = 1;  // handedness of the tangent frame: bitangent = tangent_sign * cross(n, tangent)
  // Width, in units of the first uv set, of the patch of surface the ray stands for (its ray cone where it hits):
  // image textures average their texels over it (mip-mapping). 0 reads the finest texels.
  float uv_footprint = 0;
  bool front_face = true;  // the ray arrived on the side ng points to
  // The normal of a coating layer with its own normal map (Material::coat_normal_map), world; zero when the coat
  // follows frame.n.
  Vec3 coat_normal{0, 0, 0};
  // The wavelength, in nm, the path through this point carries (spectrum.h), which dispersive materials
  // (Material::dispersive) refract by; 0 where the scene has none.
  float wavelength_nm = 0;
};

class Texture {
 public:
  virtual ~Texture() = default;
  virtual Rgb eval(const ShadingPoint& sp) const = 0;
  // Mean value over the texture's domain (for light power estimates).
  virtual Rgb average() const = 0;
};

struct RgbParam {
  Rgb value{0, 0, 0};
  std::shared_ptr<const Texture> texture;  // when set, value multiplies the texture
  Rgb eval(const ShadingPoint& sp) const { return texture ? value * texture->eval(sp) : value; }
  Rgb average() const { return texture ? value * texture->average() : value; }
};

struct FloatParam {
  float value = 0;
  std::shared_ptr<const Texture> texture;  // when set, value multiplies the texture's first channel
  float eval(const ShadingPoint& sp) const { return texture ? value * texture->eval(sp).x : value; }
};

// How an image texture is addressed: uv scaled and offset, wrapped per axis.
enum class WrapMode : uint8_t { kRepeat, kClamp, kMirror };
struct TextureMapping {
  Vec2 scale{1, 1};
  Vec2 offset{0, 0};
  float rotation = 0;                 // radians, between scale and offset, as KHR_texture_transform turns
  WrapMode wrap = WrapMode::kRepeat;  // horizontal (and vertical unless wrap_t is set)
  std::optional<WrapMode> wrap_t;     // vertical, when it differs
  int uv_set = 0;                     // 0: ShadingPoint::uv, 1: ShadingPoint::uv1
  bool operator==(const TextureMapping&) const = default;
};

// A std::allocator whose resize() leaves new elements default-initialised (for numbers: unwritten) instead of
// zeroing them: for image buffers that a decoder or a filter then writes whole, where zeroing 16 MB first costs a
// pass over memory (DamagedHelmet, five 2k textures, loads 4-8 % faster without it).
template <typename T>
struct DefaultInitAllocator : std::allocator<T> {
  template <typename U>
  struct rebind {
    using other = DefaultInitAllocator<U>;
  };
  DefaultInitAllocator() = default;
  template <typename U>
  DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}
  template <typename U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <typename U, typename... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};
template <typename T>
using PixelBuffer = std::vector<T, DefaultInitAllocator<T>>;

// 8-bit pixels already in memory (row 0 at the top), e.g. images embedded in a glTF asset.
struct ImagePixels {
  int width = 0, height = 0, channels = 0;
  PixelBuffer<uint8_t> data;
};

// An image file read through OpenImageIO, bilinearly filtered. `channel` < 0 returns RGB (grey images repeat their
// channel, alpha is ignored); 0..3 returns that channel in all three components (for scalar parameters, e.g. the
// G and B channels of a glTF metallic-roughness map). `srgb` decodes 8/16-bit sRGB-encoded values to linear;
// float formats (EXR, HDR) are always read as linear. Each (file, srgb) pair is read once per process and shared
// (a texture cache); throws std::runtime_error when the file cannot be read as an image.
std::shared_ptr<const Texture> make_image_texture(const std::filesystem::path& file, bool srgb, int channel,
                                                  const TextureMapping& mapping);
// Checks from its header alone (no pixels are read) that `file` is an image make_image_texture would take; throws
// std::runtime_error as make_image_texture does. For validating a job cheaply, with stand_in_image() in its place.
void check_image_file(const std::filesystem::path& file);
// One opaque white texel: what an image checked but not read stands in for (a scene that is validated, not rendered).
std::shared_ptr<const ImagePixels> stand_in_image();
// A texture over pixels in memory; `srgb` decodes the colour channels (never alpha). Throws on bad dimensions.
std::shared_ptr<const Texture> make_image_texture(const std::shared_ptr<const ImagePixels>& pixels, bool srgb,
                                                  int channel, const TextureMapping& mapping);
// When `a` and `b` are image textures reading one channel each (below 3) of the same texels through the same
// mapping, a texture returning that image's first three channels with the same filtering, so one lookup serves both
// (component channel_a of it is a's value, bit for bit); otherwise null.
std::shared_ptr<const Texture> make_shared_channels_texture(const Texture* a, const Texture* b, int* channel_a,
                                                            int* channel_b);
// A checkerboard in uv: `a` where floor(u s) + floor(v s) is even, `b` where odd.
std::shared_ptr<const Texture> make_checker_texture(const Rgb& a, const Rgb& b, float squares_per_unit, int uv_set = 0);
// Number of distinct images read so far (for tests of the cache).
size_t texture_cache_loads();

}  // namespace tessera
