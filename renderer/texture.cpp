#include "renderer/texture.h"

#include <array>
#include <map>
#include <mutex>
#include <stdexcept>
#include <vector>

#include <OpenImageIO/imageio.h>

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
  std::vector<float> pixels;   // linear, row-major from the top row (float sources)
  std::vector<uint8_t> bytes;  // 8-bit sources, row-major from the top row
  std::shared_ptr<const ImagePixels> shared;  // or 8-bit pixels owned elsewhere (embedded images), not copied
  bool srgb = false;           // bytes of the colour channels (not alpha) are sRGB-encoded
  static const float* srgb_table() {
    static const std::array<float, 256> table = [] {
      std::array<float, 256> t{};
      for (int i = 0; i < 256; ++i) t[i] = srgb_to_linear(i / 255.0f);
      return t;
    }();
    return table.data();
  }
};

std::mutex g_cache_mutex;
std::map<std::string, std::weak_ptr<const Image>> g_cache;
size_t g_loads = 0;

std::shared_ptr<const Image> load_image(const std::filesystem::path& file, bool srgb) {
  const std::string key = file.string() + (srgb ? "|srgb" : "|linear");
  std::lock_guard<std::mutex> lock(g_cache_mutex);
  if (auto it = g_cache.find(key); it != g_cache.end()) {
    if (auto img = it->second.lock()) return img;
  }
  // Unassociated alpha: colour channels as stored (OpenImageIO would premultiply PNG alpha on read).
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(file.string(), &config);
  if (!in) throw std::runtime_error("cannot read image \"" + file.filename().string() + "\"");
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 ||
      static_cast<int64_t>(spec.width) * spec.height > (int64_t(1) << 28))
    throw std::runtime_error("image \"" + file.filename().string() + "\" has an unsupported size");
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
                          spec.format.basetype == OIIO::TypeDesc::HALF || spec.format.basetype == OIIO::TypeDesc::DOUBLE;
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
  g_cache[key] = img;
  ++g_loads;
  return img;
}

std::shared_ptr<const Image> embedded_image(const std::shared_ptr<const ImagePixels>& src, bool srgb) {
  // The pixels are shared with the glTF import; only the flag differs between sRGB and linear uses.
  auto img = std::make_shared<Image>();
  img->width = src->width;
  img->height = src->height;
  img->channels = src->channels;
  img->shared = src;
  img->srgb = srgb;
  return img;
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
    // What every fetch needs, resolved once: where the texels are, how they decode, which channels are read.
    width_ = image_->width;
    height_ = image_->height;
    channels_ = image_->channels;
    if (image_->shared) bytes_ = image_->shared->data.data();
    else if (!image_->bytes.empty()) bytes_ = image_->bytes.data();
    else floats_ = image_->pixels.data();
    if (bytes_ && image_->srgb) srgb_table_ = Image::srgb_table();
    rgb_ = channel_ < 0 && channels_ >= 3;
    read_channel_ = channel_ >= 0 ? std::min(channel_, channels_ - 1) : 0;
    average_ = Rgb(0);
    const size_t n = static_cast<size_t>(image_->width) * image_->height;
    double sum[3] = {0, 0, 0};
    for (int y = 0; y < image_->height; ++y)
      for (int x = 0; x < image_->width; ++x) {
        Rgb c = texel(x, y);
        for (int k = 0; k < 3; ++k) sum[k] += c[k];
      }
    for (int k = 0; k < 3; ++k) average_[k] = static_cast<float>(sum[k] / static_cast<double>(n));
  }

  Rgb eval(const ShadingPoint& sp) const override {
    Vec2 uv = mapping_.uv_set == 1 ? sp.uv1 : sp.uv;
    // KHR_texture_transform order: scale, then rotate, then offset.
    float su = uv.x * mapping_.scale.x, sv = uv.y * mapping_.scale.y;
    float s = cos_ * su - sin_ * sv + mapping_.offset.x;
    float t = sin_ * su + cos_ * sv + mapping_.offset.y;
    // Bilinear filtering between the four texels around (s, t); texel centres at (i + 0.5) / size.
    float x = s * width_ - 0.5f, y = t * height_ - 0.5f;
    if (!std::isfinite(x) || !std::isfinite(y)) return texel(0, 0);
    float fx = std::floor(x), fy = std::floor(y);
    float dx = x - fx, dy = y - fy;
    int x0 = static_cast<int>(clamp(fx, -1e8f, 1e8f)), y0 = static_cast<int>(clamp(fy, -1e8f, 1e8f));
    const WrapMode wrap_t = mapping_.wrap_t.value_or(mapping_.wrap);
    int xa = wrap_index(x0, width_, mapping_.wrap), xb = wrap_index(x0 + 1, width_, mapping_.wrap);
    int ya = wrap_index(y0, height_, wrap_t), yb = wrap_index(y0 + 1, height_, wrap_t);
    return texel(xa, ya) * ((1 - dx) * (1 - dy)) + texel(xb, ya) * (dx * (1 - dy)) + texel(xa, yb) * ((1 - dx) * dy) +
           texel(xb, yb) * (dx * dy);
  }
  Rgb average() const override { return average_; }

  // The RGB texture over the same texels and mapping, when `a` and `b` read single colour channels of one image.
  static std::shared_ptr<const Texture> shared_channels(const Texture* a, const Texture* b, int* ca, int* cb) {
    const auto* ta = dynamic_cast<const ImageTexture*>(a);
    const auto* tb = dynamic_cast<const ImageTexture*>(b);
    if (!ta || !tb || ta->rgb_ || tb->rgb_ || ta->channels_ < 3 || ta->channel_ > 2 || tb->channel_ > 2) return nullptr;
    if (ta->bytes_ != tb->bytes_ || ta->floats_ != tb->floats_ || ta->srgb_table_ != tb->srgb_table_ ||
        ta->width_ != tb->width_ || ta->height_ != tb->height_ || ta->channels_ != tb->channels_)
      return nullptr;
    if (ta->mapping_ != tb->mapping_) return nullptr;
    *ca = ta->read_channel_;
    *cb = tb->read_channel_;
    return std::make_shared<ImageTexture>(ta->image_, -1, ta->mapping_);
  }

 private:
  // The texel's value as the image stores it decoded, read through the pointers resolved at construction.
  float decode(const uint8_t* b, int c) const {
    return (srgb_table_ && c < 3) ? srgb_table_[b[c]] : b[c] * (1.0f / 255.0f);
  }
  Rgb texel(int x, int y) const {
    const size_t i = (static_cast<size_t>(y) * static_cast<size_t>(width_) + static_cast<size_t>(x)) * channels_;
    if (rgb_) {
      if (floats_) return Rgb(floats_[i], floats_[i + 1], floats_[i + 2]);
      return Rgb(decode(bytes_ + i, 0), decode(bytes_ + i, 1), decode(bytes_ + i, 2));
    }
    return Rgb(floats_ ? floats_[i + read_channel_] : decode(bytes_ + i, read_channel_));
  }

  std::shared_ptr<const Image> image_;
  int width_ = 0, height_ = 0, channels_ = 0;
  const uint8_t* bytes_ = nullptr;  // 8-bit texels, or
  const float* floats_ = nullptr;   // linear float texels
  const float* srgb_table_ = nullptr;  // set when 8-bit colour channels are sRGB-encoded
  bool rgb_ = false;                   // three channels read; else one (read_channel_) repeated
  int read_channel_ = 0;
  int channel_;
  TextureMapping mapping_;
  float cos_, sin_;
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

size_t texture_cache_loads() {
  std::lock_guard<std::mutex> lock(g_cache_mutex);
  return g_loads;
}

}  // namespace tessera
