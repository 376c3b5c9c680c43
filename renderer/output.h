// The one way a film becomes files: resolve → post stages → encode → publish. The daemon (a job's results and its
// previews) and the command line (`tessera render`, `tessera merge`) both run it; they differ only in where the
// encoded bytes are published (a job's files, fenced by its run; paths on the user's disk).
//
//   resolve   the film's sums divided by their sample counts: a linear image of named layers, the beauty first
//   post      stages that change the resolved image in order: the job's denoiser (denoise.h), which reads passes
//             the job may not have asked for (they are resolved for it, and left out of the encoded image)
//   encode    each format the job asks for, in memory: OpenEXR (every layer, linear, half or float channels) and
//             PNG (the beauty, exposed and tone-mapped to 8-bit sRGB)
//   publish   the caller's: it receives each format's bytes
//
// Encoding is deterministic: the same film gives the same bytes (no time stamps), so renders are compared with cmp.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "renderer/display.h"
#include "renderer/film.h"
#include "renderer/image.h"
#include "renderer/render_settings.h"

namespace tessera {

enum class ImageFormat { kPng, kExr };
// ".png", ".exr"
const char* image_format_extension(ImageFormat format);
// The format a file name's extension names (case-insensitive), or nothing.
std::optional<ImageFormat> image_format_of(std::string_view path);

struct EncodeOptions {
  DisplaySettings display;  // PNG: exposure and tone curve
  bool exr_half = true;     // EXR channel precision, where a layer does not ask for float
};

// resolve: the beauty (Film::resolve) as the layer every image has, then the passes `aovs` (aov.h, in the table's
// order) as layers of their names.
Image resolve_image(const Film& film, const std::vector<std::string>& aovs = {});

// encode: the image in `format`. PNG holds the beauty alone; EXR every layer, the beauty as R, G, B and each other
// layer's channels as <layer>.<channel> (a layer named_in_full by its channels' own names), with the image's
// metadata as string attributes, zip-compressed. Throws std::runtime_error with OpenImageIO's message.
std::string encode_image(const Image& image, ImageFormat format, const EncodeOptions& options);

// A pass of `image` (a layer of that name, aov.h) as PNG, for a look at it (aov_look): throws std::invalid_argument
// when the image has no such layer.
std::string encode_pass_png(const Image& image, std::string_view pass);

class OutputPipeline {
 public:
  // Receives each format's encoded bytes, in the order of formats().
  using Publish = std::function<void(ImageFormat format, std::string_view bytes)>;

  // `aovs`: the passes the images hold beside the beauty (aov.h); `denoise`: the denoiser that post-processes them,
  // whose features the film must hold (film_aovs), and whose "noisy" layer the images hold too.
  OutputPipeline(EncodeOptions options, std::vector<ImageFormat> formats, std::vector<std::string> aovs = {},
                 Denoiser denoise = Denoiser::kNone);
  // A job's: its display settings, EXR precision, passes and denoiser, the formats its outputs ask for (PNG, then
  // EXR).
  OutputPipeline(const RenderSettings& settings, const OutputSpec& outputs);

  void add_post_stage(std::shared_ptr<const PostStage> stage);
  const std::vector<ImageFormat>& formats() const { return formats_; }

  // resolve → post stages.
  Image image(const Film& film) const;
  // encode → publish: each format encoded from `image` (what image() gave) and handed to `publish`.
  void publish(const Image& image, const Publish& publish) const;
  // The whole pipeline.
  void run(const Film& film, const Publish& publish) const { this->publish(image(film), publish); }
  // Each pass of `image` (the layers after the beauty) as PNG (encode_pass_png), to `publish` with its name; a layer
  // that is no pass (the denoiser's "noisy") as the beauty is shown.
  void publish_passes(const Image& image,
                      const std::function<void(std::string_view pass, std::string_view png)>& publish) const;
  // A render's preview: the image as PNG, whatever the formats.
  std::string preview_png(const Image& image) const;
  // A pass's preview: the beauty as rendered so far, before the post stages (a denoiser takes seconds at 1080p, which
  // every pass would wait for); the passes are not resolved for it.
  std::string preview_png(const Film& film) const { return preview_png(resolve_image(film)); }

 private:
  EncodeOptions options_;
  std::vector<ImageFormat> formats_;
  std::vector<std::string> aovs_;
  std::vector<std::string> resolved_;  // aovs_ and the passes the post stages read
  std::vector<std::shared_ptr<const PostStage>> post_;
};

}  // namespace tessera
