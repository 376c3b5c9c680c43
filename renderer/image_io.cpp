#include "renderer/image_io.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <cmath>
#include <stdexcept>

namespace tessera {

bool parse_tonemap(const std::string& name, ToneMap* out) {
  if (name == "clamp") *out = ToneMap::kClamp;
  else if (name == "aces" || name == "filmic") *out = ToneMap::kAces;
  else return false;
  return true;
}

const char* tonemap_name(ToneMap t) { return t == ToneMap::kAces ? "aces" : "clamp"; }

namespace {

// Narkowicz's fit of the ACES reference rendering transform with its output transform, applied per channel.
float aces_fit(float x) {
  const float a = 2.51f, b = 0.03f, c = 2.43f, d = 0.59f, e = 0.14f;
  return clamp((x * (a * x + b)) / (x * (c * x + d) + e), 0.0f, 1.0f);
}

float srgb_encode(float linear) {
  if (!(linear > 0)) return 0;
  if (linear >= 1) return 1;
  return linear <= 0.0031308f ? 12.92f * linear : 1.055f * std::pow(linear, 1.0f / 2.4f) - 0.055f;
}

void check_output(OIIO::ImageOutput* out, bool ok, const std::string& what) {
  if (!ok) throw std::runtime_error(what + ": " + (out ? out->geterror() : OIIO::geterror()));
}

}  // namespace

std::vector<uint8_t> to_display(const std::vector<float>& rgb, int width, int height, const DisplaySettings& display) {
  const float scale = std::exp2(display.exposure_ev);
  std::vector<uint8_t> out(static_cast<size_t>(width) * static_cast<size_t>(height) * 3);
  for (size_t i = 0; i < out.size(); ++i) {
    float v = rgb[i] * scale;
    if (!std::isfinite(v)) v = v > 0 ? 1.0f : 0.0f;
    if (display.tonemap == ToneMap::kAces) v = aces_fit(v);
    out[i] = static_cast<uint8_t>(std::lround(srgb_encode(v) * 255.0f));
  }
  return out;
}

void write_exr(const std::string& path, const std::vector<float>& rgb, int width, int height, bool half) {
  auto out = OIIO::ImageOutput::create(path);
  if (!out) throw std::runtime_error("OpenImageIO cannot create " + path + ": " + OIIO::geterror());
  OIIO::ImageSpec spec(width, height, 3, half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT);
  spec.attribute("compression", "zip");
  spec.attribute("Software", "tessera");
  check_output(out.get(), out->open(path, spec), "open " + path);
  check_output(out.get(), out->write_image(OIIO::TypeDesc::FLOAT, rgb.data()), "write " + path);
  check_output(out.get(), out->close(), "close " + path);
}

void write_png(const std::string& path, const std::vector<float>& rgb, int width, int height,
               const DisplaySettings& display) {
  std::vector<uint8_t> pixels = to_display(rgb, width, height, display);
  auto out = OIIO::ImageOutput::create(path);
  if (!out) throw std::runtime_error("OpenImageIO cannot create " + path + ": " + OIIO::geterror());
  OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("oiio:ColorSpace", "sRGB");
  spec.attribute("Software", "tessera");
  check_output(out.get(), out->open(path, spec), "open " + path);
  check_output(out.get(), out->write_image(OIIO::TypeDesc::UINT8, pixels.data()), "write " + path);
  check_output(out.get(), out->close(), "close " + path);
}

std::vector<uint8_t> encode_png(const std::vector<float>& rgb, int width, int height, const DisplaySettings& display) {
  std::vector<uint8_t> pixels = to_display(rgb, width, height, display);
  std::vector<unsigned char> buffer;
  OIIO::Filesystem::IOVecOutput proxy(buffer);
  auto out = OIIO::ImageOutput::create("preview.png");
  if (!out) throw std::runtime_error(std::string("OpenImageIO has no PNG writer: ") + OIIO::geterror());
  OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("png:compressionLevel", 3);
  out->set_ioproxy(&proxy);
  check_output(out.get(), out->open("preview.png", spec), "open in-memory PNG");
  check_output(out.get(), out->write_image(OIIO::TypeDesc::UINT8, pixels.data()), "encode PNG");
  check_output(out.get(), out->close(), "close in-memory PNG");
  return std::vector<uint8_t>(buffer.begin(), buffer.end());
}

ImageData read_image(const std::string& path) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) throw std::runtime_error("cannot read " + path + ": " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  ImageData img;
  img.width = spec.width;
  img.height = spec.height;
  img.channels = spec.nchannels;
  img.pixels.resize(static_cast<size_t>(spec.width) * spec.height * spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, img.pixels.data()))
    throw std::runtime_error("cannot read " + path + ": " + in->geterror());
  in->close();
  return img;
}

}  // namespace tessera
