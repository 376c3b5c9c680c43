#include <gtest/gtest.h>

#include <filesystem>

#include "renderer/image_io.h"

namespace tessera {
namespace {

std::filesystem::path temp_file(const std::string& name) {
  // One folder per test process, removed when the process ends.
  static const struct Folder {
    std::filesystem::path path =
        std::filesystem::temp_directory_path() / ("tessera-image-io-" + std::to_string(::getpid()));
    ~Folder() {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  } folder;
  std::filesystem::create_directories(folder.path);
  return folder.path / name;
}

std::vector<float> gradient(int w, int h) {
  std::vector<float> rgb(static_cast<size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float* p = &rgb[(static_cast<size_t>(y) * w + x) * 3];
      p[0] = x / float(w);
      p[1] = y / float(h);
      p[2] = 4.0f;  // above 1: only EXR keeps it
    }
  return rgb;
}

TEST(ImageIo, ExrRoundTripsLinearValues) {
  auto rgb = gradient(33, 17);
  for (bool half : {true, false}) {
    auto path = temp_file(half ? "h.exr" : "f.exr");
    write_exr(path.string(), rgb, 33, 17, half);
    ImageData img = read_image(path.string());
    ASSERT_EQ(img.width, 33);
    ASSERT_EQ(img.height, 17);
    ASSERT_EQ(img.channels, 3);
    for (size_t i = 0; i < rgb.size(); ++i) EXPECT_NEAR(img.pixels[i], rgb[i], half ? 4e-3 : 0) << i;
  }
}

TEST(ImageIo, PngIsSrgbEncoded) {
  std::vector<float> rgb = {0.0f, 0.18f, 1.0f, 0.5f, 2.0f, 0.0031308f};
  auto path = temp_file("a.png");
  write_png(path.string(), rgb, 2, 1, DisplaySettings{});
  ImageData img = read_image(path.string());
  ASSERT_EQ(img.width, 2);
  ASSERT_EQ(img.channels, 3);
  EXPECT_NEAR(img.pixels[0], 0.0, 1e-6);
  EXPECT_NEAR(img.pixels[1], 0.4613, 2.0 / 255);  // sRGB(0.18)
  EXPECT_NEAR(img.pixels[2], 1.0, 1e-6);
  EXPECT_NEAR(img.pixels[3], 0.7354, 2.0 / 255);  // sRGB(0.5)
  EXPECT_NEAR(img.pixels[4], 1.0, 1e-6);          // clamped
  // In-memory encoding gives a PNG too.
  std::vector<uint8_t> bytes = encode_png(rgb, 2, 1, DisplaySettings{});
  ASSERT_GT(bytes.size(), 8u);
  EXPECT_EQ(bytes[1], 'P');
  EXPECT_EQ(bytes[2], 'N');
  EXPECT_EQ(bytes[3], 'G');
}

TEST(ImageIo, ExposureAndAcesToneCurve) {
  std::vector<float> rgb = {0.25f, 0.25f, 0.25f, 100.0f, 100.0f, 100.0f};
  DisplaySettings plus_one;
  plus_one.exposure_ev = 1;
  auto a = to_display(rgb, 2, 1, plus_one);
  auto b = to_display({0.5f, 0.5f, 0.5f}, 1, 1, DisplaySettings{});
  EXPECT_EQ(a[0], b[0]);  // +1 EV doubles the radiance
  DisplaySettings aces;
  aces.tonemap = ToneMap::kAces;
  auto c = to_display(rgb, 2, 1, aces);
  EXPECT_LT(c[0], b[0]);   // the filmic curve darkens mid-grey a little
  EXPECT_GE(c[3], 250);    // and rolls highlights off to white
}

TEST(ImageIo, UnreadableFileThrows) {
  EXPECT_THROW(read_image("/nonexistent/file.exr"), std::runtime_error);
}

}  // namespace
}  // namespace tessera
