#include "renderer/output.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cctype>
#include <stdexcept>

#include "renderer/aov.h"
#include "renderer/denoise.h"

namespace tessera {

namespace {

void check_output(OIIO::ImageOutput* out, bool ok, const std::string& what) {
  if (!ok) throw std::runtime_error(what + ": " + (out ? out->geterror() : OIIO::geterror()));
}

// Writes one image through OpenImageIO into memory (its IOVecOutput proxy): `name` only picks the format.
std::string write_in_memory(const char* name, const OIIO::ImageSpec& spec, OIIO::TypeDesc pixel_type,
                            const void* pixels) {
  std::vector<unsigned char> buffer;
  OIIO::Filesystem::IOVecOutput proxy(buffer);
  auto out = OIIO::ImageOutput::create(name);
  if (!out) throw std::runtime_error(std::string("OpenImageIO cannot write ") + name + ": " + OIIO::geterror());
  out->set_ioproxy(&proxy);
  check_output(out.get(), out->open(name, spec), std::string("open ") + name);
  check_output(out.get(), out->write_image(pixel_type, pixels), std::string("write ") + name);
  check_output(out.get(), out->close(), std::string("close ") + name);
  return std::string(buffer.begin(), buffer.end());
}

// Linear RGB as an 8-bit sRGB PNG through `display`.
std::string encode_png(const std::vector<float>& rgb, int width, int height, const DisplaySettings& display) {
  const std::vector<uint8_t> pixels = to_display(rgb, width, height, display);
  OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("oiio:ColorSpace", "sRGB");
  spec.attribute("Software", "tessera");
  // zlib level 3 of 9: a preview is encoded after every pass, where level 6 (libpng's default) costs several times
  // the time for a few per cent of size.
  spec.attribute("png:compressionLevel", 3);
  return write_in_memory("image.png", spec, OIIO::TypeDesc::UINT8, pixels.data());
}

std::string encode_exr(const Image& image, bool half) {
  const size_t pixels = static_cast<size_t>(image.width) * static_cast<size_t>(image.height);
  size_t channels = 0;
  for (const ImageLayer& layer : image.layers) {
    if (layer.channels.empty() || layer.pixels.size() != pixels * layer.channels.size())
      throw std::invalid_argument("image layer \"" + layer.name + "\" does not match its channels and size");
    channels += layer.channels.size();
  }
  const OIIO::TypeDesc precision = half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT;
  OIIO::ImageSpec spec(image.width, image.height, static_cast<int>(channels), precision);
  // The beauty alone keeps OpenImageIO's default names (R, G, B) and one format: exactly the file of a job without
  // passes. Further layers are named <layer>.<channel>, OpenEXR's convention for layers (Kainz, Bogart and Stanczyk,
  // "Technical Introduction to OpenEXR", 2013, "Layers"), each channel in its layer's precision.
  std::vector<float> interleaved;
  if (image.layers.size() > 1) {
    spec.channelnames.clear();
    for (const ImageLayer& layer : image.layers)
      for (const std::string& c : layer.channels) {
        spec.channelnames.push_back(layer.name.empty() || layer.named_in_full ? c : layer.name + "." + c);
        spec.channelformats.push_back(layer.always_float ? OIIO::TypeDesc::FLOAT : precision);
      }
    interleaved.resize(pixels * channels);
    size_t offset = 0;
    for (const ImageLayer& layer : image.layers) {
      const size_t n = layer.channels.size();
      for (size_t p = 0; p < pixels; ++p)
        std::copy_n(layer.pixels.begin() + static_cast<std::ptrdiff_t>(p * n), n,
                    interleaved.begin() + static_cast<std::ptrdiff_t>(p * channels + offset));
      offset += n;
    }
  }
  spec.attribute("compression", "zip");
  spec.attribute("Software", "tessera");
  // No time stamp: the same image is the same file, so renders are compared with cmp. OpenImageIO stamps an EXR with
  // the wall-clock time (OpenEXR's capDate, "YYYY:MM:DD hh:mm:ss") unless the spec has a DateTime: an empty one says
  // "no date" and is the same in every file.
  spec.attribute("DateTime", "");
  for (const auto& [name, value] : image.metadata) spec.attribute(name, value);
  return write_in_memory("image.exr", spec, OIIO::TypeDesc::FLOAT,
                         image.layers.size() > 1 ? interleaved.data() : image.beauty().pixels.data());
}

}  // namespace

const char* image_format_extension(ImageFormat format) {
  return format == ImageFormat::kPng ? ".png" : ".exr";
}

std::optional<ImageFormat> image_format_of(std::string_view path) {
  const size_t dot = path.rfind('.');
  if (dot == std::string_view::npos) return std::nullopt;
  std::string ext(path.substr(dot));
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  for (ImageFormat f : {ImageFormat::kPng, ImageFormat::kExr})
    if (ext == image_format_extension(f)) return f;
  return std::nullopt;
}

Image resolve_image(const Film& film, const std::vector<std::string>& aovs) {
  Image image;
  image.width = film.width();
  image.height = film.height();
  image.layers.push_back(ImageLayer{"", {"R", "G", "B"}, film.resolve(), false});
  for (const AovInfo& aov : aov_table()) {
    if (std::find(aovs.begin(), aovs.end(), aov.name) == aovs.end()) continue;
    ImageLayer layer{std::string(aov.name), {}, resolve_aov(film, aov), aov.always_float};
    if (aov.source == AovSource::kCryptomatte) {
      layer.channels = aov_channel_names(aov);
      layer.named_in_full = true;
      for (auto& attribute : cryptomatte::exr_metadata(aov.crypto_type, film.layer_at(film.layer(aov.name)).manifest))
        image.metadata.push_back(std::move(attribute));
    } else {
      for (int c = 0; c < aov.channels; ++c) layer.channels.emplace_back(aov.channel_names[static_cast<size_t>(c)]);
    }
    image.layers.push_back(std::move(layer));
  }
  return image;
}

std::string encode_image(const Image& image, ImageFormat format, const EncodeOptions& options) {
  if (image.layers.empty()) throw std::invalid_argument("an image without a beauty layer");
  return format == ImageFormat::kPng ? encode_png(image.beauty().pixels, image.width, image.height, options.display)
                                     : encode_exr(image, options.exr_half);
}

std::string encode_pass_png(const Image& image, std::string_view pass) {
  const AovInfo* aov = find_aov(pass);
  for (const ImageLayer& layer : image.layers)
    if (aov && layer.name == pass) return encode_png(aov_look(*aov, layer.pixels), image.width, image.height, {});
  throw std::invalid_argument("the image has no pass " + std::string(pass));
}

OutputPipeline::OutputPipeline(EncodeOptions options, std::vector<ImageFormat> formats, std::vector<std::string> aovs,
                               Denoiser denoise)
    : options_(options), formats_(std::move(formats)), aovs_(std::move(aovs)) {
  RenderSettings passes;
  passes.aovs = aovs_;
  passes.denoise = denoise;
  resolved_ = film_aovs(passes);
  if (auto stage = make_denoiser(denoise)) add_post_stage(std::move(stage));
}

OutputPipeline::OutputPipeline(const RenderSettings& settings, const OutputSpec& outputs)
    : OutputPipeline(EncodeOptions{settings.display, settings.exr_half}, {}, settings.aovs, settings.denoise) {
  if (outputs.png) formats_.push_back(ImageFormat::kPng);
  if (outputs.exr) formats_.push_back(ImageFormat::kExr);
}

void OutputPipeline::add_post_stage(std::shared_ptr<const PostStage> stage) {
  post_.push_back(std::move(stage));
}

Image OutputPipeline::image(const Film& film) const {
  Image image = resolve_image(film, resolved_);
  for (const auto& stage : post_) stage->apply(image);
  // The passes resolved for the stages alone are not the job's.
  std::erase_if(image.layers, [&](const ImageLayer& layer) {
    return std::find(resolved_.begin(), resolved_.end(), layer.name) != resolved_.end() &&
           std::find(aovs_.begin(), aovs_.end(), layer.name) == aovs_.end();
  });
  return image;
}

void OutputPipeline::publish(const Image& image, const Publish& publish) const {
  for (ImageFormat f : formats_) publish(f, encode_image(image, f, options_));
}

void OutputPipeline::publish_passes(const Image& image,
                                    const std::function<void(std::string_view, std::string_view)>& publish) const {
  for (size_t i = 1; i < image.layers.size(); ++i) {
    const ImageLayer& layer = image.layers[i];
    if (find_aov(layer.name) || layer.channels.size() != 3)
      publish(layer.name, encode_pass_png(image, layer.name));
    else
      publish(layer.name, encode_png(layer.pixels, image.width, image.height, options_.display));
  }
}

std::string OutputPipeline::preview_png(const Image& image) const {
  return encode_image(image, ImageFormat::kPng, options_);
}

}  // namespace tessera
