#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <thread>
#include <vector>

#include <OpenImageIO/imageio.h>

#include "renderer/gltf/loader.h"
#include "renderer/image_io.h"
#include "renderer/output.h"
#include "tests/renderer/gltf_fixture.h"

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

// An RGB image through the output pipeline's encoders (renderer/output.h), in memory or to a file.
Image rgb_image(const std::vector<float>& rgb, int w, int h) {
  return Image{w, h, {ImageLayer{"", {"R", "G", "B"}, rgb, false, false}}, {}};
}
std::vector<uint8_t> encode_png(const std::vector<float>& rgb, int w, int h, const DisplaySettings& display) {
  const std::string bytes = encode_image(rgb_image(rgb, w, h), ImageFormat::kPng, EncodeOptions{display, true});
  return std::vector<uint8_t>(bytes.begin(), bytes.end());
}
void write_png(const std::string& path, const std::vector<float>& rgb, int w, int h, const DisplaySettings& display) {
  std::ofstream(path, std::ios::binary) << encode_image(rgb_image(rgb, w, h), ImageFormat::kPng,
                                                        EncodeOptions{display, true});
}
void write_exr(const std::string& path, const std::vector<float>& rgb, int w, int h, bool half) {
  std::ofstream(path, std::ios::binary) << encode_image(rgb_image(rgb, w, h), ImageFormat::kExr,
                                                        EncodeOptions{{}, half});
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

std::string file_bytes(const std::filesystem::path& path);

// The same image is the same file whenever it is written: no time stamp (OpenEXR's capDate) in the header.
TEST(ImageIo, ExrFilesCarryNoTimeStamp) {
  const auto rgb = gradient(8, 8);
  const auto path = temp_file("stamp.exr");
  write_exr(path.string(), rgb, 8, 8, true);
  auto in = OIIO::ImageInput::open(path.string());
  ASSERT_TRUE(in);
  EXPECT_EQ(in->spec().get_string_attribute("DateTime"), "");
  in->close();
  const std::string first = file_bytes(path);
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));  // another second of the clock
  write_exr(path.string(), rgb, 8, 8, true);
  EXPECT_TRUE(file_bytes(path) == first) << "the second write differs from the first";
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
  EXPECT_LT(c[0], b[0]);  // the filmic curve darkens mid-grey a little
  EXPECT_GE(c[3], 250);   // and rolls highlights off to white
}

// Writes a w x h float EXR of `channels` channels (values[i] is texel i's channel values).
std::filesystem::path write_channels(const std::string& name, int w, int h, int channels,
                                     const std::vector<float>& values) {
  const auto path = temp_file(name);
  auto out = OIIO::ImageOutput::create(path.string());
  OIIO::ImageSpec spec(w, h, channels, OIIO::TypeDesc::FLOAT);
  if (channels == 2) spec.alpha_channel = 1;
  EXPECT_TRUE(out && out->open(path.string(), spec) && out->write_image(OIIO::TypeDesc::FLOAT, values.data()));
  out->close();
  return path;
}

// A read of a set number of channels takes the first ones stored, repeats a grey image's one over red, green and
// blue (grey and alpha: the alpha goes to the fourth channel, never to green), fills missing ones with 0, and leaves
// extra ones on disk.
TEST(ImageIo, ReadsAGivenNumberOfChannels) {
  struct Case {
    int stored;
    std::vector<float> texel;
    int wanted;
    std::vector<float> expected;
  };
  const std::vector<Case> cases = {{4, {0.1f, 0.2f, 0.3f, 0.4f}, 3, {0.1f, 0.2f, 0.3f}},
                                   {3, {0.1f, 0.2f, 0.3f}, 4, {0.1f, 0.2f, 0.3f, 0}},
                                   {1, {0.7f}, 3, {0.7f, 0.7f, 0.7f}},
                                   {2, {0.7f, 0.25f}, 3, {0.7f, 0.7f, 0.7f}},
                                   {2, {0.7f, 0.25f}, 4, {0.7f, 0.7f, 0.7f, 0.25f}},
                                   {4, {0.1f, 0.2f, 0.3f, 0.4f}, 0, {0.1f, 0.2f, 0.3f, 0.4f}}};
  for (size_t k = 0; k < cases.size(); ++k) {
    const Case& c = cases[k];
    SCOPED_TRACE("stored " + std::to_string(c.stored) + ", read " + std::to_string(c.wanted));
    std::vector<float> values;
    for (int t = 0; t < 3 * 2; ++t) values.insert(values.end(), c.texel.begin(), c.texel.end());
    const auto path = write_channels(std::string("c").append(std::to_string(k)) + ".exr", 3, 2, c.stored, values);
    const ImageData img = read_image(path.string(), c.wanted);
    ASSERT_EQ(img.channels, static_cast<int>(c.expected.size()));
    ASSERT_EQ(img.pixels.size(), 3u * 2u * c.expected.size());
    for (size_t i = 0; i < img.pixels.size(); ++i)
      EXPECT_FLOAT_EQ(img.pixels[i], c.expected[i % c.expected.size()]) << "value " << i;
  }
}

// A read into the caller's memory asks where once it knows the size, writes the channels asked for at the stride
// given (grey repeated as above), and leaves the rest of each texel as it was.
TEST(ImageIo, ReadsIntoTheCallersMemoryAtAStride) {
  for (int stored : {3, 1}) {
    SCOPED_TRACE("stored " + std::to_string(stored));
    std::vector<float> values;
    for (int t = 0; t < 3 * 2; ++t)
      for (int c = 0; c < stored; ++c) values.push_back(0.1f * t + 0.01f * c);
    const auto path = write_channels("s" + std::to_string(stored) + ".exr", 3, 2, stored, values);
    std::vector<float> memory;
    int asked_w = 0, asked_h = 0;
    read_image_into(path.string(), 3, 5, 0, 0, [&](int w, int h) {
      asked_w = w;
      asked_h = h;
      memory.assign(static_cast<size_t>(w) * h * 5, -1.0f);
      return memory.data();
    });
    ASSERT_EQ(asked_w, 3);
    ASSERT_EQ(asked_h, 2);
    for (int t = 0; t < 3 * 2; ++t) {
      for (int c = 0; c < 3; ++c)
        EXPECT_FLOAT_EQ(memory[t * 5 + c], 0.1f * t + 0.01f * (stored == 1 ? 0 : c)) << "texel " << t << " " << c;
      EXPECT_EQ(memory[t * 5 + 3], -1.0f);
      EXPECT_EQ(memory[t * 5 + 4], -1.0f);
    }
  }
  // The limits are checked before memory is asked for.
  const auto path = write_channels("s.exr", 3, 2, 3, std::vector<float>(3 * 2 * 3, 1.0f));
  bool asked = false;
  EXPECT_THROW(read_image_into(path.string(), 3, 4, 5, 0,
                               [&](int, int) {
                                 asked = true;
                                 return static_cast<float*>(nullptr);
                               }),
               std::runtime_error);
  EXPECT_FALSE(asked);
}

// An image larger than allowed is refused from its header, naming its size.
TEST(ImageIo, ImagesAboveTheTexelLimitAreRefused) {
  const auto path = write_channels("big.exr", 8, 4, 3, std::vector<float>(8 * 4 * 3, 1.0f));
  EXPECT_NO_THROW(read_image(path.string(), 3, 32, 8));
  try {
    read_image(path.string(), 3, 0, 7);
    ADD_FAILURE() << "an image over the width limit was read";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("it is 8 texels wide, more than the 7 allowed"), std::string::npos)
        << e.what();
  }
  try {
    read_image(path.string(), 3, 31);
    ADD_FAILURE() << "an image over the limit was read";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("8x4 is larger than the 31 texels allowed"), std::string::npos) << e.what();
  }
}

std::string file_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// The first `bytes` bytes of `path`, written to a file named `name`.
std::filesystem::path truncated_copy(const std::filesystem::path& path, size_t bytes, const std::string& name) {
  const std::string data = file_bytes(path);
  EXPECT_LT(bytes, data.size()) << "nothing to cut from " << path;
  const auto cut = temp_file(name);
  std::ofstream(cut, std::ios::binary) << data.substr(0, bytes);
  return cut;
}

// A header read gives the size without the pixels, JPEG (baseline and progressive, through libjpeg) and others
// alike, under the same limits and errors as a full read. Without the pixels: the header of a file cut short before
// its pixel data reads as well as the whole file's.
TEST(ImageIo, HeadersAreReadWithoutThePixels) {
  for (bool progressive : {false, true}) {
    const auto path = temp_file(progressive ? "p.jpg" : "b.jpg");
    auto out = OIIO::ImageOutput::create(path.string());
    OIIO::ImageSpec spec(40, 30, 3, OIIO::TypeDesc::UINT8);
    if (progressive) spec.attribute("jpeg:progressive", 1);
    ASSERT_TRUE(out->open(path.string(), spec));
    std::vector<unsigned char> rgb(40 * 30 * 3, 200);
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, rgb.data()));
    out->close();
    // The start of scan marker (FF DA) and its segment: what follows is entropy-coded pixels, cut here.
    const std::string jpeg = file_bytes(path);
    const size_t sos = jpeg.find("\xff\xda");
    ASSERT_NE(sos, std::string::npos);
    const size_t sos_length =
        (static_cast<unsigned char>(jpeg[sos + 2]) << 8) | static_cast<unsigned char>(jpeg[sos + 3]);
    const auto header_only = truncated_copy(path, sos + 2 + sos_length, progressive ? "p-cut.jpg" : "b-cut.jpg");
    for (const auto& file : {path, header_only}) {
      const ImageHeader h = read_image_header(file.string());
      EXPECT_EQ(h.width, 40) << file;
      EXPECT_EQ(h.height, 30) << file;
      EXPECT_EQ(h.channels, 3) << file;
      EXPECT_THROW(read_image_header(file.string(), 1199), std::runtime_error);
      EXPECT_THROW(read_image_header(file.string(), 0, 39), std::runtime_error);
    }
    EXPECT_THROW(read_image(header_only.string()), std::runtime_error) << "the cut JPEG has no pixels to read";
  }
  const auto exr = write_channels("h.exr", 8, 4, 2, std::vector<float>(8 * 4 * 2, 0.5f));
  // An EXR's header is its magic number and version, then attributes (name, type, size, value) up to a null byte;
  // the offset table follows (OpenEXR reads it on open), then the pixels from the first offset on.
  const std::string bytes = file_bytes(exr);
  size_t end = 8;
  while (end < bytes.size() && bytes[end] != 0) {
    end = bytes.find('\0', end) + 1;  // the name
    end = bytes.find('\0', end) + 1;  // the type
    ASSERT_LE(end + 4, bytes.size());
    int32_t size = 0;
    std::memcpy(&size, bytes.data() + end, 4);
    end += 4 + static_cast<size_t>(size);
  }
  ASSERT_LE(end + 9, bytes.size());
  uint64_t first_chunk = 0;
  std::memcpy(&first_chunk, bytes.data() + end + 1, 8);
  const auto exr_cut = truncated_copy(exr, first_chunk, "h-cut.exr");
  for (const auto& file : {exr, exr_cut}) {
    const ImageHeader h = read_image_header(file.string());
    EXPECT_EQ(h.width, 8) << file;
    EXPECT_EQ(h.height, 4) << file;
    EXPECT_EQ(h.channels, 2) << file;
  }
  EXPECT_THROW(read_image(exr_cut.string()), std::runtime_error) << "the cut EXR has no pixels to read";
  const auto text = temp_file("text.jpg");
  std::ofstream(text) << "\xff\xd8 not really";
  EXPECT_THROW(read_image_header(text.string()), std::runtime_error);
}

// A JPEG is complete when its markers lead to the end-of-image marker: no proper prefix of a file is, the file is,
// and so is the file with data after it (phones append a video to a photo) or with stray bytes between segments;
// read_image refuses a cut file.
TEST(ImageIo, TruncatedJpegsAreToldFromWholeOnes) {
  for (bool progressive : {false, true}) {
    SCOPED_TRACE(progressive ? "progressive" : "baseline");
    const auto path = temp_file(progressive ? "whole-p.jpg" : "whole-b.jpg");
    auto out = OIIO::ImageOutput::create(path.string());
    OIIO::ImageSpec spec(24, 16, 3, OIIO::TypeDesc::UINT8);
    if (progressive) spec.attribute("jpeg:progressive", 1);
    ASSERT_TRUE(out->open(path.string(), spec));
    std::vector<unsigned char> rgb(24 * 16 * 3);
    for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = static_cast<unsigned char>(i * 37);  // busy: many stuffed FFs
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, rgb.data()));
    out->close();
    const std::string whole = file_bytes(path);
    const std::vector<unsigned char> bytes(whole.begin(), whole.end());
    EXPECT_TRUE(jpeg_complete(bytes.data(), bytes.size()));
    size_t prefixes_taken_whole = 0;
    for (size_t n = 0; n < bytes.size(); ++n) prefixes_taken_whole += jpeg_complete(bytes.data(), n);
    EXPECT_EQ(prefixes_taken_whole, 0u);
    std::vector<unsigned char> appended = bytes;
    for (int i = 0; i < 64; ++i) appended.push_back(static_cast<unsigned char>(i % 3 ? 0xFF : i));
    EXPECT_TRUE(jpeg_complete(appended.data(), appended.size()));
    // Stray bytes between two segments (after the first, whose length follows its marker) are skipped, as libjpeg
    // skips them.
    ASSERT_EQ(bytes[2], 0xFF);
    std::vector<unsigned char> stray = bytes;
    stray.insert(stray.begin() + 4 + ((bytes[4] << 8) | bytes[5]), {0x00, 0x12, 0x34});
    EXPECT_TRUE(jpeg_complete(stray.data(), stray.size()));
    std::ofstream(temp_file("stray.jpg"), std::ios::binary)
        .write(reinterpret_cast<const char*>(stray.data()), static_cast<std::streamsize>(stray.size()));
    EXPECT_NO_THROW(read_image(temp_file("stray.jpg").string()));
    const auto cut = truncated_copy(path, bytes.size() - 10, progressive ? "cut-p.jpg" : "cut-b.jpg");  // in a scan
    try {
      read_image(cut.string());
      ADD_FAILURE() << "a cut JPEG was read";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("ends before its end-of-image marker"), std::string::npos) << e.what();
    }
    EXPECT_NO_THROW(read_image(path.string()));
  }
}

// A PNG is complete when its chunks are whole up to its IEND chunk: no proper prefix of a file is, the file is, and
// so is the file with data after it; read_image refuses a cut file (OpenImageIO 2.4.7 would lose the memory of its
// error message reading it: see png_complete), and read_image_header one cut before its image data.
TEST(ImageIo, TruncatedPngsAreToldFromWholeOnes) {
  const auto path = temp_file("whole.png");
  auto out = OIIO::ImageOutput::create(path.string());
  OIIO::ImageSpec spec(24, 16, 3, OIIO::TypeDesc::UINT8);
  ASSERT_TRUE(out->open(path.string(), spec));
  std::vector<unsigned char> rgb(24 * 16 * 3);
  for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = static_cast<unsigned char>(i * 37);
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, rgb.data()));
  out->close();
  const std::string whole = file_bytes(path);
  const std::vector<unsigned char> bytes(whole.begin(), whole.end());
  EXPECT_TRUE(png_complete(bytes.data(), bytes.size()));
  EXPECT_TRUE(truncation(bytes.data(), bytes.size()).empty());
  size_t prefixes_taken_whole = 0;
  for (size_t n = 0; n < bytes.size(); ++n) prefixes_taken_whole += png_complete(bytes.data(), n);
  EXPECT_EQ(prefixes_taken_whole, 0u);
  std::vector<unsigned char> appended = bytes;
  appended.insert(appended.end(), 64, 0xFF);
  EXPECT_TRUE(png_complete(appended.data(), appended.size()));
  // A chunk whose length reaches past the end of the data (2^32 - 1, beyond any size_t sum of a 32-bit length).
  std::vector<unsigned char> long_chunk = bytes;
  std::fill(long_chunk.begin() + 8, long_chunk.begin() + 12, 0xFF);
  EXPECT_FALSE(png_complete(long_chunk.data(), long_chunk.size()));
  const auto cut = truncated_copy(path, bytes.size() - 30, "cut.png");  // in the image data
  try {
    read_image(cut.string());
    ADD_FAILURE() << "a cut PNG was read";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cut.png: it is a truncated PNG"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(read_image(path.string()));
  // A header read reads the chunks before the image data: a file cut in its pixels has a header, one cut before them
  // has none.
  EXPECT_EQ(read_image_header(cut.string()).width, 24);
  const size_t image_data = whole.find("IDAT");
  ASSERT_NE(image_data, std::string::npos);
  const auto cut_header = truncated_copy(path, image_data - 7, "cut-header.png");
  try {
    read_image_header(cut_header.string());
    ADD_FAILURE() << "the header of a PNG cut before its image data was read";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cut-header.png: it is a truncated PNG"), std::string::npos) << e.what();
  }
}

// An ICC profile (ICC.1:2001-04, section 6: a 128-byte header, a tag count, a tag table) whose `tags` tags all hold
// one XYZType value under signatures made from `seed`, none of them a tag OpenImageIO knows by name.
std::vector<unsigned char> icc_profile_with_unknown_tags(int seed, int tags) {
  std::vector<unsigned char> p(128 + 4 + 12 * static_cast<size_t>(tags), 0);
  auto be32 = [&](size_t at, uint32_t v) {
    for (int i = 0; i < 4; ++i) p[at + i] = static_cast<unsigned char>(v >> (24 - 8 * i));
  };
  be32(8, 0x02100000);  // version 2.1
  std::memcpy(&p[12], "mntrRGB XYZ ", 12);
  std::memcpy(&p[36], "acsp", 4);
  be32(128, static_cast<uint32_t>(tags));
  for (int t = 0; t < tags; ++t) {
    const size_t at = 132 + 12 * static_cast<size_t>(t);
    const int id = seed * tags + t;
    const char signature[4] = {static_cast<char>('a' + id % 26), static_cast<char>('a' + id / 26 % 26),
                               static_cast<char>('a' + id / 676 % 26), static_cast<char>('A' + id / 17576 % 26)};
    std::memcpy(&p[at], signature, 4);
    be32(at + 4, static_cast<uint32_t>(p.size()));
    be32(at + 8, 20);
    const unsigned char xyz[20] = {'X', 'Y', 'Z', ' '};
    p.insert(p.end(), xyz, xyz + 20);
  }
  be32(0, static_cast<uint32_t>(p.size()));
  return p;
}

void write_jpeg_with_icc_profile(const std::filesystem::path& path, const std::vector<unsigned char>& profile) {
  OIIO::ImageSpec spec(8, 8, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("ICCProfile", OIIO::TypeDesc(OIIO::TypeDesc::UINT8, static_cast<int>(profile.size())), profile.data());
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out && out->open(path.string(), spec));
  const std::vector<unsigned char> pixels(8 * 8 * 3, 128);
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
  out->close();
}

// Debian 12's OpenImageIO (2.4.7) decodes a JPEG's ICC profile on open with lookups that insert each tag name it has
// not seen into a table shared by the process: two threads opening such JPEGs at once corrupt it and crash. Every
// reader of the renderer opens through one lock (open_image_input): here many threads read JPEGs whose profiles hold
// thousands of names new to the process, through read_image and through the glTF importer's parallel texture
// decoding, and all of them are read. Without the lock this test process segfaults in two runs of three on a 2-core
// machine.
TEST(ImageIo, JpegsWithIccProfilesAreReadOnManyThreadsAtOnce) {
  constexpr int kThreads = 8, kFilesPerThread = 60, kTags = 400;
  std::vector<std::filesystem::path> files;
  for (int f = 0; f < kThreads * kFilesPerThread; ++f) {
    files.push_back(temp_file("icc" + std::to_string(f) + ".jpg"));
    write_jpeg_with_icc_profile(files.back(), icc_profile_with_unknown_tags(f, kTags));
  }
  // The same count of assets, each of kFilesPerThread JPEG images beside it, with signatures new again.
  std::vector<std::filesystem::path> assets;
  for (int a = 0; a < kThreads; ++a) {
    const std::filesystem::path dir = temp_file("icc-asset" + std::to_string(a));
    test::GltfBuilder b;
    b.doc["images"] = nlohmann::json::array();
    for (int i = 0; i < kFilesPerThread; ++i) {
      const std::string name = std::string("t").append(std::to_string(i)) + ".jpg";
      std::filesystem::create_directories(dir);
      write_jpeg_with_icc_profile(dir / name,
                                  icc_profile_with_unknown_tags(kThreads * kFilesPerThread * (a + 1) + i, kTags));
      b.doc["images"].push_back({{"uri", name}});
    }
    b.node({{"mesh", b.mesh({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}, -1)}}, true);
    assets.push_back(b.write(dir, "asset"));
  }
  std::atomic<int> read{0}, imported{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      for (int i = 0; i < kFilesPerThread; ++i)
        if (read_image(files[static_cast<size_t>(t * kFilesPerThread + i)].string()).width == 8) ++read;
      Scene scene;
      import_gltf(assets[static_cast<size_t>(t)], "/scene/gltf", scene, {});
      ++imported;
    });
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(read.load(), kThreads * kFilesPerThread);
  EXPECT_EQ(imported.load(), kThreads);
}

// OpenEXR 3.1 allocates the size a header attribute declares before reading it: a 32-byte file declaring a 2 GiB
// string made the daemon allocate 2 GiB (found by fuzz_image). Such a header is refused from its bytes, before
// OpenEXR sees it, through every reader; a sound EXR (as write_exr writes them) passes.
TEST(ImageIo, AnExrHeaderDeclaringMoreThanTheFileHoldsIsRefused) {
  std::vector<unsigned char> bad = {0x76, 0x2F, 0x31, 0x01, 2, 0, 0, 0};  // magic, version 2
  for (const char* text : {"comments", "string"}) bad.insert(bad.end(), text, text + std::strlen(text) + 1);
  bad.insert(bad.end(), {0xF0, 0xFF, 0xFF, 0x7F, 'o', 'i', 'i', 'o'});  // declares 2147483632 bytes, holds 4
  EXPECT_NE(exr_header_problem(bad.data(), bad.size())
                .find("its header attribute \"comments\" declares 2147483632 bytes, more than the file holds"),
            std::string::npos)
      << exr_header_problem(bad.data(), bad.size());
  const auto path = temp_file("declares-2gib.exr");
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bad.data()), static_cast<long>(bad.size()));
  for (auto read :
       {+[](const std::string& p) { read_image_header(p); }, +[](const std::string& p) { read_image(p); }}) {
    try {
      read(path.string());
      ADD_FAILURE() << "read";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("declares-2gib.exr: its header attribute \"comments\" declares"),
                std::string::npos)
          << e.what();
    }
  }
  const auto good = temp_file("sound.exr");
  write_exr(good.string(), gradient(8, 4), 8, 4, true);
  std::ifstream in(good, std::ios::binary);
  const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(exr_header_problem(bytes.data(), bytes.size()), "");
  EXPECT_EQ(read_image_header(good.string()).width, 8);
}

// The message names the file but not the folder it is in (a daemon's data directory).
TEST(ImageIo, UnreadableFileThrows) {
  EXPECT_THROW(read_image("/nonexistent/file.exr"), std::runtime_error);
  EXPECT_THROW(read_image("tessera-no-such-file.exr"), std::runtime_error);  // a bare name: nothing to scrub
  const auto path = temp_file("not-an-image.exr");
  std::ofstream(path) << "plain text";
  try {
    read_image(path.string());
    ADD_FAILURE() << "text was read as an image";
  } catch (const std::runtime_error& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("not-an-image.exr"), std::string::npos) << message;
    EXPECT_EQ(message.find(path.parent_path().string()), std::string::npos) << message;
  }
}

}  // namespace
}  // namespace tessera
