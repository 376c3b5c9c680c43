#include "renderer/output.h"

#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

namespace tessera {
namespace {

// The spec of encoded image data (and its pixels, as float), read back by OpenImageIO from a file of its bytes.
OIIO::ImageSpec spec_of(const std::string& bytes, const char* name, std::vector<float>* pixels = nullptr) {
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() / ("tessera-output-" + std::to_string(::getpid()) + "-" + name);
  std::ofstream(path, std::ios::binary) << bytes;
  auto in = OIIO::ImageInput::open(path.string());
  EXPECT_TRUE(in) << OIIO::geterror();
  OIIO::ImageSpec spec;
  if (in) {
    spec = in->spec();
    if (pixels) {
      pixels->resize(spec.image_pixels() * static_cast<size_t>(spec.nchannels));
      EXPECT_TRUE(in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, pixels->data()));
    }
    in->close();
  }
  std::filesystem::remove(path);
  return spec;
}

Film grey_film(int w, int h, float value) {
  Film film(w, h);
  const float rgb[3] = {value, value, value};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) film.add_layer_sample(0, x, y, rgb);
  film.set_samples(1);
  return film;
}

TEST(Output, FormatsAreNamedByTheirExtension) {
  EXPECT_EQ(image_format_of("a/b/result.PNG"), ImageFormat::kPng);
  EXPECT_EQ(image_format_of("x.exr"), ImageFormat::kExr);
  EXPECT_EQ(image_format_of("x.tfilm"), std::nullopt);
  EXPECT_EQ(image_format_of("exr"), std::nullopt);
}

// The beauty alone is the file a job without passes has always had: three channels R, G, B in the job's precision.
TEST(Output, TheBeautyAloneIsAnRgbExr) {
  Image image{4, 2, {ImageLayer{"", {"R", "G", "B"}, std::vector<float>(4 * 2 * 3, 0.25f), false, false}}, {}};
  const OIIO::ImageSpec spec = spec_of(encode_image(image, ImageFormat::kExr, EncodeOptions{{}, true}), "a.exr");
  ASSERT_EQ(spec.nchannels, 3);
  EXPECT_EQ(spec.channelnames, (std::vector<std::string>{"R", "G", "B"}));
  EXPECT_EQ(spec.format, OIIO::TypeDesc::HALF);
  EXPECT_EQ(spec.get_string_attribute("compression"), "zip");
}

// Further layers are <layer>.<channel>, each in its precision: a layer that asks for float is float in a half EXR.
TEST(Output, LayersAreNamedChannelsOfOneExr) {
  const int w = 3, h = 2;
  std::vector<float> depth(w * h);
  for (size_t i = 0; i < depth.size(); ++i) depth[i] = 1000.0f + 0.001f * static_cast<float>(i);  // not a half
  Image image{w,
              h,
              {ImageLayer{"", {"R", "G", "B"}, std::vector<float>(w * h * 3, 0.5f), false},
               ImageLayer{"normal", {"X", "Y", "Z"}, std::vector<float>(w * h * 3, -0.75f), false},
               ImageLayer{"depth", {"Z"}, depth, true, false}},
              {}};
  std::vector<float> pixels;
  const OIIO::ImageSpec spec =
      spec_of(encode_image(image, ImageFormat::kExr, EncodeOptions{{}, true}), "a.exr", &pixels);
  ASSERT_EQ(spec.nchannels, 7);
  // OpenEXR stores channels sorted by name; OpenImageIO reads them back in its own order, so look them up by name.
  for (const char* name : {"R", "G", "B", "normal.X", "normal.Y", "normal.Z", "depth.Z"})
    EXPECT_GE(spec.channelindex(name), 0) << name;
  const int z = spec.channelindex("depth.Z"), nx = spec.channelindex("normal.X");
  ASSERT_GE(z, 0);
  ASSERT_GE(nx, 0);
  EXPECT_EQ(spec.channelformat(z), OIIO::TypeDesc::FLOAT);
  EXPECT_EQ(spec.channelformat(nx), OIIO::TypeDesc::HALF);
  for (size_t p = 0; p < depth.size(); ++p) {
    EXPECT_EQ(pixels[p * 7 + static_cast<size_t>(z)], depth[p]) << p;
    EXPECT_EQ(pixels[p * 7 + static_cast<size_t>(nx)], -0.75f) << p;
  }
}

// A post stage changes the image between resolve and encode, for the results and the preview alike.
class Halve final : public PostStage {
 public:
  const char* name() const override { return "halve"; }
  void apply(Image& image) const override {
    for (float& v : image.layers.front().pixels) v *= 0.5f;
  }
};

TEST(Output, PostStagesRunBetweenResolveAndEncode) {
  const Film film = grey_film(2, 2, 0.8f);
  OutputPipeline pipeline(EncodeOptions{{}, false}, {ImageFormat::kExr, ImageFormat::kPng});
  pipeline.add_post_stage(std::make_shared<Halve>());
  std::vector<ImageFormat> published;
  pipeline.run(film, [&](ImageFormat format, std::string_view bytes) {
    published.push_back(format);
    if (format != ImageFormat::kExr) return;
    std::vector<float> pixels;
    spec_of(std::string(bytes), "a.exr", &pixels);
    for (float v : pixels) EXPECT_FLOAT_EQ(v, 0.4f);
  });
  EXPECT_EQ(published, (std::vector<ImageFormat>{ImageFormat::kExr, ImageFormat::kPng}));
  // A pass's preview is the film as rendered, before the post stages; the preview of a finished image has them.
  std::vector<float> pass_preview, image_preview;
  spec_of(pipeline.preview_png(film), "a.png", &pass_preview);
  spec_of(pipeline.preview_png(pipeline.image(film)), "b.png", &image_preview);
  OutputPipeline plain(EncodeOptions{{}, false}, {});
  std::vector<float> unhalved;
  spec_of(plain.preview_png(film), "c.png", &unhalved);
  ASSERT_EQ(pass_preview.size(), unhalved.size());
  EXPECT_EQ(pass_preview, unhalved);
  ASSERT_EQ(image_preview.size(), unhalved.size());
  EXPECT_LT(image_preview[0], unhalved[0]);
}

// A job's pipeline writes the formats its outputs ask for, PNG first.
TEST(Output, AJobsPipelineWritesWhatItsOutputsAskFor) {
  RenderSettings settings;
  EXPECT_EQ(OutputPipeline(settings, OutputSpec{true, true}).formats(),
            (std::vector<ImageFormat>{ImageFormat::kPng, ImageFormat::kExr}));
  EXPECT_EQ(OutputPipeline(settings, OutputSpec{false, true}).formats(), std::vector<ImageFormat>{ImageFormat::kExr});
  int published = 0;
  OutputPipeline(settings, OutputSpec{false, false}).run(grey_film(1, 1, 1), [&](ImageFormat, std::string_view) {
    ++published;
  });
  EXPECT_EQ(published, 0);
}

}  // namespace
}  // namespace tessera
