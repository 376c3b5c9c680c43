#include "renderer/texture.h"

#include <array>
#include <atomic>
#include <stdexcept>
#include <vector>

#include <OpenImageIO/imageio.h>

#include "renderer/image_input.h"
#include "renderer/image_io.h"
#include "renderer/once_cache.h"
#include "renderer/thread_pool.h"

namespace tessera {

namespace {

// IEC 61966-2-1 sRGB decoding.
float srgb_to_linear(float v) {
  return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

// Texels are kept as 8-bit where the source is 8-bit (decoded through a lookup table at each fetch: a 2048^2 RGBA
// texture takes 16 MB, not 64 MB as floats), and as linear floats otherwise (EXR, HDR, 16-bit).
struct Image {
  int width = 0, height = 0, channels = 0;
  PixelBuffer<float> pixels;                  // linear, row-major from the top row (float sources)
  PixelBuffer<uint8_t> bytes;                 // 8-bit sources, row-major from the top row
  std::shared_ptr<const ImagePixels> shared;  // or 8-bit pixels owned elsewhere (embedded images), not copied
  bool srgb = false;                          // bytes of the colour channels (not alpha) are sRGB-encoded
  // Mip levels 1, 2, ... (level 0 is the image itself), each half the size of the one before (rounded up) down to
  // 1x1, averaged in linear values and stored as the image is (8-bit sRGB-encoded bytes, or floats).
  struct Level {
    int width = 0, height = 0;
    PixelBuffer<uint8_t> bytes;
    PixelBuffer<float> pixels;
  };
  std::vector<Level> mips;
  std::array<float, 4> mean{};  // of level 0's linear values, per channel (the first four)
  static const float* srgb_table() {
    static const std::array<float, 256> table = [] {
      std::array<float, 256> t{};
      for (int i = 0; i < 256; ++i) t[i] = srgb_to_linear(i / 255.0f);
      return t;
    }();
    return table.data();
  }
};

// The 8-bit sRGB code whose decoded value is nearest `linear`: a first guess from a table over [0, 1], then a step
// or two among the midpoints between codes.
uint8_t linear_to_srgb_byte(float linear) {
  struct Tables {
    std::array<float, 256> midpoints{};  // midpoints[i]: between codes i and i + 1 (the last is above 1)
    std::array<uint8_t, 1025> guess{};   // the code for linear = k / 1024, rounded down
  };
  static const Tables tables = [] {
    Tables t;
    const float* decode = Image::srgb_table();
    for (int i = 0; i < 255; ++i) t.midpoints[i] = 0.5f * (decode[i] + decode[i + 1]);
    t.midpoints[255] = kInfinity;
    int code = 0;
    for (int k = 0; k <= 1024; ++k) {
      while (code < 255 && t.midpoints[code] <= k / 1024.0f) ++code;
      t.guess[k] = static_cast<uint8_t>(code);
    }
    return t;
  }();
  const float v = clamp(linear, 0.0f, 1.0f);
  int code = tables.guess[static_cast<int>(v * 1024)];
  while (v >= tables.midpoints[code]) ++code;
  return static_cast<uint8_t>(code);
}

// Adds the first N channels of a row of w texels (`stride` values apart) to `sum`, in registers.
template <int N>
void sum_row(const float* row, int w, int stride, std::array<double, 4>* sum) {
  double s[N] = {};
  for (int x = 0; x < w; ++x)
    for (int c = 0; c < N; ++c) s[c] += row[static_cast<size_t>(x) * stride + c];
  for (int c = 0; c < N; ++c) (*sum)[c] += s[c];
}

// Builds `img`'s mip levels from level 0 (`bytes` or `floats`): each texel of a level is the mean of the 2x2 texels
// below it (the last row or column repeated where the size is odd), in linear values, so that averages are of light
// rather than of encoded values. Also sets img->mean. Rows of a large level are made in parallel, each from its own
// two source rows; per-row sums are added in row order, so the mean does not depend on the number of threads.
void build_mips(Image* img, const uint8_t* bytes, const float* floats) {
  const int channels = img->channels;
  const float* srgb = Image::srgb_table();
  float decode[4][256];  // per channel: byte to linear
  for (int c = 0; c < 4; ++c)
    for (int i = 0; i < 256; ++i) decode[c][i] = img->srgb && c < 3 ? srgb[i] : i * (1.0f / 255.0f);
  // Row `r` of level 0 as linear floats.
  auto level0_row = [&](int r, float* out) {
    const size_t row_values = static_cast<size_t>(img->width) * channels, first = static_cast<size_t>(r) * row_values;
    if (floats)
      std::copy_n(&floats[first], row_values, out);
    else
      for (size_t i = 0; i < row_values; i += channels)
        for (int c = 0; c < channels; ++c) out[i + c] = decode[std::min(c, 3)][bytes[first + i + c]];
  };
  auto add_row = [channels](const float* row, int w, std::array<double, 4>* sum) {
    switch (std::min(channels, 4)) {
      case 1:
        sum_row<1>(row, w, channels, sum);
        break;
      case 2:
        sum_row<2>(row, w, channels, sum);
        break;
      case 3:
        sum_row<3>(row, w, channels, sum);
        break;
      default:
        sum_row<4>(row, w, channels, sum);
        break;
    }
  };
  int w = img->width, h = img->height;
  std::array<double, 4> total{};
  if (w == 1 && h == 1) {
    std::vector<float> row(channels);
    level0_row(0, row.data());
    add_row(row.data(), 1, &total);
  }
  PixelBuffer<float> prev, next;
  while (w > 1 || h > 1) {
    const int nw = (w + 1) / 2, nh = (h + 1) / 2;
    const bool from_level0 = prev.empty();
    next.resize(static_cast<size_t>(nw) * nh * channels);
    Image::Level level;
    level.width = nw;
    level.height = nh;
    if (bytes) level.bytes.resize(next.size());
    std::vector<std::array<double, 4>> row_sums(from_level0 ? nh : 0);
    const size_t row_values = static_cast<size_t>(w) * channels;
    auto make_rows = [&](int y_begin, int y_end) {
      std::vector<float> rows(2 * row_values);
      for (int y = y_begin; y < y_end; ++y) {
        // The two source rows as linear floats (the second is the first again at an odd height's last row).
        for (int j = 0; j < 2; ++j) {
          const int r = std::min(2 * y + j, h - 1);
          float* out = &rows[j * row_values];
          if (!from_level0)
            std::copy_n(&prev[static_cast<size_t>(r) * row_values], row_values, out);
          else
            level0_row(r, out);
          if (from_level0 && 2 * y + j < h) add_row(out, w, &row_sums[y]);
        }
        const size_t first = static_cast<size_t>(y) * nw * channels;
        float* out = &next[first];
        for (int x = 0; x < nw; ++x) {
          const size_t a = static_cast<size_t>(2 * x) * channels;
          const size_t b = static_cast<size_t>(std::min(2 * x + 1, w - 1)) * channels;
          for (int c = 0; c < channels; ++c)
            out[x * channels + c] =
                0.25f * (rows[a + c] + rows[b + c] + rows[row_values + a + c] + rows[row_values + b + c]);
        }
        if (bytes)
          for (size_t i = 0; i < static_cast<size_t>(nw) * channels; i += channels)
            for (int c = 0; c < channels; ++c)
              level.bytes[first + i + c] = img->srgb && c < 3
                                               ? linear_to_srgb_byte(out[i + c])
                                               : static_cast<uint8_t>(std::lround(clamp(out[i + c], 0.0f, 1.0f) * 255));
      }
    };
    // About 64k source texels per item: levels below that are one item, made on this thread.
    const int rows_per_item = std::max(1, 32768 / std::max(w, 1));
    run_in_parallel((static_cast<size_t>(nh) + rows_per_item - 1) / rows_per_item, [&](size_t i) {
      const int y0 = static_cast<int>(i) * rows_per_item;
      make_rows(y0, std::min(nh, y0 + rows_per_item));
    });
    for (const std::array<double, 4>& sum : row_sums)
      for (int c = 0; c < 4; ++c) total[c] += sum[c];
    if (!bytes) level.pixels = next;
    img->mips.push_back(std::move(level));
    std::swap(prev, next);
    w = nw;
    h = nh;
  }
  const double texels = static_cast<double>(img->width) * img->height;
  for (int c = 0; c < 4; ++c) img->mean[c] = static_cast<float>(total[c] / texels);
}

// Largest image file a texture reads (2^28 texels).
constexpr size_t kMaxTextureTexels = size_t{1} << 28;

// Decoded images by file and colour space, or by embedded pixels: read once however many materials and jobs ask.
OnceCache<Image>& image_cache() {
  static OnceCache<Image> cache;
  return cache;
}
std::atomic<size_t> g_loads{0};

// Opens an image file and checks its header: a size and channel count a texture takes. Throws std::runtime_error
// naming the file (not its folder).
std::unique_ptr<OIIO::ImageInput> open_image_file(const std::filesystem::path& file) {
  // Unassociated alpha: colour channels as stored (OpenImageIO would premultiply PNG alpha on read).
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = open_image_input(file.string(), &config);
  if (!in) throw std::runtime_error("cannot read image \"" + file.filename().string() + "\"");
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 ||
      static_cast<size_t>(spec.width) * static_cast<size_t>(spec.height) > kMaxTextureTexels)
    throw std::runtime_error("image \"" + file.filename().string() + "\" has an unsupported size");
  return in;
}

std::shared_ptr<const Image> load_image(const std::filesystem::path& file, bool srgb) {
  const std::string key = file.string() + (srgb ? "|srgb" : "|linear");
  return image_cache().get(key, [&]() -> std::shared_ptr<const Image> {
    auto in = open_image_file(file);
    const OIIO::ImageSpec& spec = in->spec();
    auto img = std::make_shared<Image>();
    img->width = spec.width;
    img->height = spec.height;
    img->channels = spec.nchannels;
    const size_t count = static_cast<size_t>(spec.width) * spec.height * spec.nchannels;
    bool ok;
    if (spec.format.basetype == OIIO::TypeDesc::UINT8) {
      img->bytes.resize(count);
      img->srgb = srgb;
      ok = in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, img->bytes.data());
    } else {
      const bool is_float = spec.format.basetype == OIIO::TypeDesc::FLOAT ||
                            spec.format.basetype == OIIO::TypeDesc::HALF ||
                            spec.format.basetype == OIIO::TypeDesc::DOUBLE;
      img->pixels.resize(count);
      ok = in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, img->pixels.data());
      if (ok && srgb && !is_float) {
        const int colour_channels = std::min(spec.nchannels, 3);
        for (size_t i = 0; i < img->pixels.size(); ++i)
          if (static_cast<int>(i % spec.nchannels) < colour_channels) img->pixels[i] = srgb_to_linear(img->pixels[i]);
      }
    }
    if (!ok) throw std::runtime_error("cannot decode image \"" + file.filename().string() + "\"");
    in->close();
    build_mips(img.get(), img->bytes.empty() ? nullptr : img->bytes.data(),
               img->pixels.empty() ? nullptr : img->pixels.data());
    ++g_loads;
    return img;
  });
}

std::shared_ptr<const Image> embedded_image(const std::shared_ptr<const ImagePixels>& src, bool srgb) {
  // The pixels are shared with the glTF import; only the flag differs between sRGB and linear uses. Textures over
  // the same pixels with the same flag (a metallic-roughness map read twice) share one Image and its mip levels; the
  // key's address cannot be reused while the Image, which holds the pixels, lives.
  char key[64];
  std::snprintf(key, sizeof key, "embedded:%p|%d", static_cast<const void*>(src.get()), srgb ? 1 : 0);
  return image_cache().get(key, [&]() -> std::shared_ptr<const Image> {
    auto img = std::make_shared<Image>();
    img->width = src->width;
    img->height = src->height;
    img->channels = src->channels;
    img->shared = src;
    img->srgb = srgb;
    build_mips(img.get(), src->data.data(), nullptr);
    return img;
  });
}

// Wraps integer texel coordinate i into [0, n).
int wrap_index(int i, int n, WrapMode mode) {
  if (static_cast<unsigned>(i) < static_cast<unsigned>(n)) return i;  // inside: every mode leaves it alone
  switch (mode) {
    case WrapMode::kRepeat: {
      int r = i % n;
      return r < 0 ? r + n : r;
    }
    case WrapMode::kClamp:
      return clamp(i, 0, n - 1);
    case WrapMode::kMirror: {
      int period = 2 * n;
      int r = i % period;
      if (r < 0) r += period;
      return r < n ? r : period - 1 - r;
    }
  }
  return 0;
}

class ImageTexture final : public Texture {
 public:
  ImageTexture(std::shared_ptr<const Image> image, int channel, const TextureMapping& mapping)
      : image_(std::move(image)),
        channel_(channel),
        mapping_(mapping),
        cos_(std::cos(mapping.rotation)),
        sin_(std::sin(mapping.rotation)) {
    // What every fetch needs, resolved once: where each level's texels are, how they decode, which channels are read.
    channels_ = image_->channels;
    LevelView base{image_->width, image_->height, nullptr, nullptr};
    if (image_->shared)
      base.bytes = image_->shared->data.data();
    else if (!image_->bytes.empty())
      base.bytes = image_->bytes.data();
    else
      base.floats = image_->pixels.data();
    levels_.push_back(base);
    for (const Image::Level& l : image_->mips)
      levels_.push_back({l.width, l.height, l.bytes.empty() ? nullptr : l.bytes.data(),
                         l.pixels.empty() ? nullptr : l.pixels.data()});
    if (base.bytes && image_->srgb) srgb_table_ = Image::srgb_table();
    rgb_ = channel_ < 0 && channels_ >= 3;
    read_channel_ = channel_ >= 0 ? std::min(channel_, channels_ - 1) : 0;
    // A footprint of one uv unit covers this many texels of level 0 (across, the geometric mean of both axes).
    texels_per_uv_ = std::sqrt(static_cast<float>(base.width) * std::abs(mapping_.scale.x) *
                               static_cast<float>(base.height) * std::abs(mapping_.scale.y));
    // The mean of the texels read, from the one build_mips took over level 0.
    const std::array<float, 4>& mean = image_->mean;
    average_ = rgb_ ? Rgb(mean[0], mean[1], mean[2]) : Rgb(mean[std::min(read_channel_, 3)]);
  }

  Rgb eval(const ShadingPoint& sp) const override {
    Vec2 uv = mapping_.uv_set == 1 ? sp.uv1 : sp.uv;
    // KHR_texture_transform: scale, then rotate, then offset, as its matrix T * R * S with R = [cos sin; -sin cos]
    // (the extension's specification, "Transform"): counter-clockwise as the texture is seen, its v axis pointing down.
    float su = uv.x * mapping_.scale.x, sv = uv.y * mapping_.scale.y;
    float s = cos_ * su + sin_ * sv + mapping_.offset.x;
    float t = -sin_ * su + cos_ * sv + mapping_.offset.y;
    // Trilinear filtering: the level where the footprint is one texel wide, blended with the next coarser one.
    const float texels = sp.uv_footprint * texels_per_uv_;
    if (!(texels > 1)) return bilinear(levels_[0], s, t);
    const float level = std::log2(texels);
    const int last = static_cast<int>(levels_.size()) - 1;
    if (!(level < static_cast<float>(last))) return bilinear(levels_[last], s, t);
    const int l0 = static_cast<int>(level);
    const float f = level - static_cast<float>(l0);
    return bilinear(levels_[l0], s, t) * (1 - f) + bilinear(levels_[l0 + 1], s, t) * f;
  }
  Rgb average() const override { return average_; }

  // The RGB texture over the same texels and mapping, when `a` and `b` read single colour channels of one image.
  static std::shared_ptr<const Texture> shared_channels(const Texture* a, const Texture* b, int* ca, int* cb) {
    const auto* ta = dynamic_cast<const ImageTexture*>(a);
    const auto* tb = dynamic_cast<const ImageTexture*>(b);
    if (!ta || !tb || ta->rgb_ || tb->rgb_ || ta->channels_ < 3 || ta->channel_ > 2 || tb->channel_ > 2) return nullptr;
    // Textures over the same pixels decoded the same way share their Image (the caches above).
    if (ta->image_ != tb->image_) return nullptr;
    if (ta->mapping_ != tb->mapping_) return nullptr;
    *ca = ta->read_channel_;
    *cb = tb->read_channel_;
    return std::make_shared<ImageTexture>(ta->image_, -1, ta->mapping_);
  }

 private:
  struct LevelView {
    int width, height;
    const uint8_t* bytes;  // 8-bit texels, or
    const float* floats;   // linear float texels
  };
  // The texel's value as the image stores it decoded, read through the pointers resolved at construction.
  float decode(const uint8_t* b, int c) const {
    return (srgb_table_ && c < 3) ? srgb_table_[b[c]] : b[c] * (1.0f / 255.0f);
  }
  Rgb texel(const LevelView& l, int x, int y) const {
    const size_t i = (static_cast<size_t>(y) * static_cast<size_t>(l.width) + static_cast<size_t>(x)) * channels_;
    if (rgb_) {
      if (l.floats) return Rgb(l.floats[i], l.floats[i + 1], l.floats[i + 2]);
      return Rgb(decode(l.bytes + i, 0), decode(l.bytes + i, 1), decode(l.bytes + i, 2));
    }
    return Rgb(l.floats ? l.floats[i + read_channel_] : decode(l.bytes + i, read_channel_));
  }
  // Bilinear filtering between the four texels of level `l` around (s, t); texel centres at (i + 0.5) / size.
  Rgb bilinear(const LevelView& l, float s, float t) const {
    float x = s * l.width - 0.5f, y = t * l.height - 0.5f;
    if (!std::isfinite(x) || !std::isfinite(y)) return texel(l, 0, 0);
    float fx = std::floor(x), fy = std::floor(y);
    float dx = x - fx, dy = y - fy;
    int x0 = static_cast<int>(clamp(fx, -1e8f, 1e8f)), y0 = static_cast<int>(clamp(fy, -1e8f, 1e8f));
    const WrapMode wrap_t = mapping_.wrap_t.value_or(mapping_.wrap);
    int xa = wrap_index(x0, l.width, mapping_.wrap), xb = wrap_index(x0 + 1, l.width, mapping_.wrap);
    int ya = wrap_index(y0, l.height, wrap_t), yb = wrap_index(y0 + 1, l.height, wrap_t);
    return texel(l, xa, ya) * ((1 - dx) * (1 - dy)) + texel(l, xb, ya) * (dx * (1 - dy)) +
           texel(l, xa, yb) * ((1 - dx) * dy) + texel(l, xb, yb) * (dx * dy);
  }

  std::shared_ptr<const Image> image_;
  int channels_ = 0;
  std::vector<LevelView> levels_;      // level 0 (the image) first, then its mips
  const float* srgb_table_ = nullptr;  // set when 8-bit colour channels are sRGB-encoded
  bool rgb_ = false;                   // three channels read; else one (read_channel_) repeated
  int read_channel_ = 0;
  int channel_;
  TextureMapping mapping_;
  float cos_, sin_;
  float texels_per_uv_ = 0;
  Rgb average_;
};

class CheckerTexture final : public Texture {
 public:
  CheckerTexture(const Rgb& a, const Rgb& b, float scale, int uv_set) : a_(a), b_(b), scale_(scale), uv_set_(uv_set) {}
  Rgb eval(const ShadingPoint& sp) const override {
    Vec2 uv = uv_set_ == 1 ? sp.uv1 : sp.uv;
    double iu = std::floor(static_cast<double>(uv.x) * scale_), iv = std::floor(static_cast<double>(uv.y) * scale_);
    return std::fmod(std::abs(iu + iv), 2.0) < 0.5 ? a_ : b_;
  }
  Rgb average() const override { return (a_ + b_) * 0.5f; }

 private:
  Rgb a_, b_;
  float scale_;
  int uv_set_;
};

}  // namespace

std::shared_ptr<const Texture> make_image_texture(const std::filesystem::path& file, bool srgb, int channel,
                                                  const TextureMapping& mapping) {
  return std::make_shared<ImageTexture>(load_image(file, srgb), channel, mapping);
}

std::shared_ptr<const Texture> make_image_texture(const std::shared_ptr<const ImagePixels>& pixels, bool srgb,
                                                  int channel, const TextureMapping& mapping) {
  if (!pixels || pixels->width <= 0 || pixels->height <= 0 || pixels->channels <= 0 ||
      pixels->data.size() != static_cast<size_t>(pixels->width) * pixels->height * pixels->channels)
    throw std::runtime_error("an embedded image has inconsistent dimensions");
  return std::make_shared<ImageTexture>(embedded_image(pixels, srgb), channel, mapping);
}

std::shared_ptr<const Texture> make_shared_channels_texture(const Texture* a, const Texture* b, int* channel_a,
                                                            int* channel_b) {
  return ImageTexture::shared_channels(a, b, channel_a, channel_b);
}

std::shared_ptr<const Texture> make_checker_texture(const Rgb& a, const Rgb& b, float squares_per_unit, int uv_set) {
  return std::make_shared<CheckerTexture>(a, b, squares_per_unit, uv_set);
}

void check_image_file(const std::filesystem::path& file) {
  read_image_header(file.string(), kMaxTextureTexels);
}

std::shared_ptr<const ImagePixels> stand_in_image() {
  static const std::shared_ptr<const ImagePixels> texel = [] {
    auto pixels = std::make_shared<ImagePixels>();
    pixels->width = pixels->height = 1;
    pixels->channels = 4;
    pixels->data.assign(4, 255);
    return pixels;
  }();
  return texel;
}

size_t texture_cache_loads() {
  return g_loads.load();
}

}  // namespace tessera
