#include "renderer/image_io.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <mutex>
#include <stdexcept>
#include <vector>

#include <jpeglib.h>  // after <cstdio>: it uses FILE without including it

#include "renderer/image_input.h"

namespace tessera {

namespace {

// The file's name for messages: not where it lies (a daemon's data directory is not the client's business).
std::string file_name(const std::string& path) {
  return std::filesystem::path(path).filename().string();
}

// `message` with every mention of `path` (OpenImageIO quotes it) replaced by the file's name.
std::string scrub(std::string message, const std::string& path) {
  const std::string name = file_name(path);
  if (path.empty() || path == name) return message;
  for (size_t at = message.find(path); at != std::string::npos; at = message.find(path, at + name.size()))
    message.replace(at, path.size(), name);
  return message;
}

// The limits of read_image applied to a header.
void check_limits(const ImageHeader& h, const std::string& path, size_t max_texels, int max_width) {
  const std::string name = file_name(path);
  if (max_texels > 0 && static_cast<size_t>(h.width) * static_cast<size_t>(h.height) > max_texels)
    throw std::runtime_error("cannot read " + name + ": " + std::to_string(h.width) + "x" + std::to_string(h.height) +
                             " is larger than the " + std::to_string(max_texels) + " texels allowed");
  if (max_width > 0 && h.width > max_width)
    throw std::runtime_error("cannot read " + name + ": it is " + std::to_string(h.width) +
                             " texels wide, more than the " + std::to_string(max_width) + " allowed");
}

// Opens an image and checks its header against the limits; throws std::runtime_error naming the file.
std::unique_ptr<OIIO::ImageInput> open_checked(const std::string& path, size_t max_texels, int max_width) {
  const std::string name = file_name(path);
  auto in = open_image_input(path);
  if (!in) throw std::runtime_error("cannot read " + name + ": " + scrub(OIIO::geterror(), path));
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
    throw std::runtime_error("cannot read " + name + ": it has no pixels");
  check_limits({spec.width, spec.height, spec.nchannels}, path, max_texels, max_width);
  return in;
}

// libjpeg reports errors by calling error_exit, which must not return: it jumps back to the setjmp in
// read_jpeg_header (no C++ object with a destructor lives between the two).
struct JpegErrors {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
};
[[noreturn]] void jpeg_error_exit(j_common_ptr info) {
  std::longjmp(reinterpret_cast<JpegErrors*>(info->err)->jump, 1);
}
void jpeg_no_message(j_common_ptr, int) {}

// A JPEG header from memory or from an open file (one of the two), read with jpeg_read_header: markers up to the
// frame header, no scan. False when it is not readable JPEG.
bool read_jpeg_header(const unsigned char* bytes, size_t size, std::FILE* file, ImageHeader* out) {
  jpeg_decompress_struct info;
  JpegErrors errors;
  info.err = jpeg_std_error(&errors.mgr);
  errors.mgr.error_exit = jpeg_error_exit;
  errors.mgr.emit_message = jpeg_no_message;
  if (setjmp(errors.jump)) {
    jpeg_destroy_decompress(&info);
    return false;
  }
  jpeg_create_decompress(&info);
  if (file)
    jpeg_stdio_src(&info, file);
  else
    jpeg_mem_src(&info, bytes, static_cast<unsigned long>(size));
  const bool ok = jpeg_read_header(&info, TRUE) == JPEG_HEADER_OK;
  *out = {static_cast<int>(info.image_width), static_cast<int>(info.image_height), info.num_components};
  jpeg_destroy_decompress(&info);
  return ok && out->width > 0 && out->height > 0;
}

constexpr unsigned char kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
// OpenEXR's magic number, 20000630 as a little-endian 32-bit integer (OpenEXR file layout, "Magic Number").
constexpr unsigned char kExrMagic[4] = {0x76, 0x2F, 0x31, 0x01};

// Walks the chunks of PNG data of `size` bytes (PNG specification, 2nd edition, 5.3: a 4-byte big-endian length, a
// 4-byte type, the data, a 4-byte CRC), reading the 8 bytes of a chunk's length and type with chunk_at(offset, out):
// true when every chunk is whole up to the IEND chunk or, with `header_only`, up to the first IDAT chunk (what
// reading the header reads).
bool png_chunks_whole(size_t size, bool header_only, const std::function<bool(size_t, unsigned char*)>& chunk_at) {
  for (size_t i = 8; size >= i && size - i >= 12;) {
    unsigned char chunk[8];
    if (!chunk_at(i, chunk)) return false;
    const size_t length = (static_cast<size_t>(chunk[0]) << 24) | (static_cast<size_t>(chunk[1]) << 16) |
                          (static_cast<size_t>(chunk[2]) << 8) | chunk[3];
    if (header_only && std::memcmp(chunk + 4, "IDAT", 4) == 0) return true;  // however long it is
    if (length > size - i - 12) return false;
    if (std::memcmp(chunk + 4, "IEND", 4) == 0) return true;
    i += 12 + length;
  }
  return false;
}

// OpenEXR's header (OpenEXR file layout, "Header"): after the magic number and a 4-byte version field, attributes,
// each a name and a type name ending in a NUL, a 32-bit little-endian size and that many bytes of value; an empty
// name ends a header, and a multi-part file (version bit 12) has several, ended by an empty one. OpenEXR 3.1 (Debian
// 12 has 3.1.5) allocates the size an attribute declares before it reads the value, so a 32-byte file declaring a
// 2 GiB string allocates 2 GiB (found by fuzz_image). Each declared size is held to the bytes the file has, reading
// with read_at(offset, n, out) (n bytes, false past the end); an empty string, or what is wrong.
std::string exr_attributes_problem(size_t size,
                                   const std::function<bool(size_t offset, size_t n, unsigned char* out)>& read_at) {
  unsigned char version[4];
  if (!read_at(4, 4, version)) return "its header is cut short";
  const bool multipart = (version[1] & 0x10) != 0;
  size_t at = 8;
  constexpr int kMaxAttributes = 100000;
  for (int attributes = 0, empty_in_a_row = 0; attributes < kMaxAttributes; ++attributes) {
    // The name and the type name, each at most 255 bytes and a NUL.
    std::string parts[2];
    for (std::string& part : parts) {
      unsigned char text[256];
      const size_t n = std::min<size_t>(sizeof text, size - std::min(size, at));
      if (n == 0 || !read_at(at, n, text)) return "its header is cut short";
      const unsigned char* end = static_cast<const unsigned char*>(std::memchr(text, 0, n));
      if (!end) return "an attribute name in its header is not ended";
      part.assign(reinterpret_cast<const char*>(text), static_cast<size_t>(end - text));
      at += part.size() + 1;
      if (part.empty()) break;  // an empty name ends a header: there is no type name
    }
    if (parts[0].empty()) {
      if (!multipart || ++empty_in_a_row == 2) return {};
      continue;
    }
    empty_in_a_row = 0;
    unsigned char length[4];
    if (!read_at(at, 4, length)) return "its header is cut short";
    const uint32_t declared = static_cast<uint32_t>(length[0]) | (static_cast<uint32_t>(length[1]) << 8) |
                              (static_cast<uint32_t>(length[2]) << 16) | (static_cast<uint32_t>(length[3]) << 24);
    at += 4;
    if (declared > size - std::min(size, at))
      return "its header attribute \"" + parts[0].substr(0, 64) + "\" declares " + std::to_string(declared) +
             " bytes, more than the file holds";
    at += declared;
  }
  return "its header has too many attributes";
}

// Whether the PNG file holds its chunks whole up to its image data, read chunk header by chunk header.
bool png_header_whole(std::FILE* file) {
  if (std::fseek(file, 0, SEEK_END) != 0) return false;
  const long size = std::ftell(file);
  return size > 0 && png_chunks_whole(static_cast<size_t>(size), true, [&](size_t offset, unsigned char* out) {
           return std::fseek(file, static_cast<long>(offset), SEEK_SET) == 0 && std::fread(out, 1, 8, file) == 8;
         });
}

}  // namespace

std::optional<ImageHeader> jpeg_header(const unsigned char* bytes, size_t size) {
  ImageHeader header;
  if (size < 2 || bytes[0] != 0xFF || bytes[1] != 0xD8 || !read_jpeg_header(bytes, size, nullptr, &header))
    return std::nullopt;
  return header;
}

ImageHeader read_image_header(const std::string& path, size_t max_texels, int max_width) {
  if (std::FILE* file = std::fopen(path.c_str(), "rb")) {
    unsigned char magic[8] = {};
    const size_t got = std::fread(magic, 1, sizeof magic, file);
    const bool jpeg = got >= 2 && magic[0] == 0xFF && magic[1] == 0xD8;
    // Only the chunks up to the image data: the header of a PNG cut short in its pixels reads as the whole file's.
    const bool cut_png = got == 8 && std::memcmp(magic, kPngSignature, 8) == 0 && !png_header_whole(file);
    ImageHeader header;
    const bool read = jpeg && std::fseek(file, 0, SEEK_SET) == 0 && read_jpeg_header(nullptr, 0, file, &header);
    std::fclose(file);
    if (cut_png)
      throw std::runtime_error("cannot read " + file_name(path) +
                               ": it is a truncated PNG (its data ends before its image data)");
    if (read) {
      check_limits(header, path, max_texels, max_width);
      return header;
    }
    // Not JPEG, or JPEG libjpeg cannot read: OpenImageIO decides, and words the error.
  }
  auto in = open_checked(path, max_texels, max_width);
  ImageHeader header{in->spec().width, in->spec().height, in->spec().nchannels};
  in->close();
  return header;
}

bool jpeg_complete(const unsigned char* bytes, size_t size) {
  // Marker segments from after SOI: FF, fill bytes FF, the marker code, then (but for RSTn and TEM) a 16-bit length
  // that counts itself. After a start of scan comes entropy-coded data, in which an FF is followed by 00 (a stuffed
  // byte) or by a restart marker; any other code ends the scan (progressive files have many).
  // Stray bytes between segments are skipped as libjpeg skips them (with a warning), not refused.
  size_t i = 2;
  while (i + 1 < size) {
    if (bytes[i] != 0xFF) {
      const void* next = std::memchr(bytes + i, 0xFF, size - i);
      if (!next) return false;
      i = static_cast<size_t>(static_cast<const unsigned char*>(next) - bytes);
      continue;
    }
    const unsigned char code = bytes[i + 1];
    if (code == 0xFF) {  // a fill byte
      ++i;
      continue;
    }
    if (code == 0xD9) return true;  // EOI
    if (code == 0x00 || (code >= 0xD0 && code <= 0xD7) || code == 0x01) {
      i += 2;  // stuffed byte, restart marker or TEM: no length
      continue;
    }
    if (i + 3 >= size) return false;
    const size_t length = (static_cast<size_t>(bytes[i + 2]) << 8) | bytes[i + 3];
    if (length < 2) return false;
    i += 2 + length;  // after an SOS header, the entropy-coded data: the skip above walks it
  }
  return false;
}

bool png_complete(const unsigned char* bytes, size_t size) {
  return png_chunks_whole(size, false, [&](size_t offset, unsigned char* out) {
    std::memcpy(out, bytes + offset, 8);
    return true;
  });
}

std::string exr_header_problem(const unsigned char* bytes, size_t size) {
  if (size < 4 || std::memcmp(bytes, kExrMagic, 4) != 0) return {};
  return exr_attributes_problem(size, [&](size_t offset, size_t n, unsigned char* out) {
    if (offset > size || n > size - offset) return false;
    std::memcpy(out, bytes + offset, n);
    return true;
  });
}

std::string truncation(const unsigned char* bytes, size_t size) {
  if (size >= 2 && bytes[0] == 0xFF && bytes[1] == 0xD8 && !jpeg_complete(bytes, size))
    return "a truncated JPEG (its data ends before its end-of-image marker)";
  if (size >= 8 && std::memcmp(bytes, kPngSignature, 8) == 0 && !png_complete(bytes, size))
    return "a truncated PNG (its data ends before its IEND chunk)";
  return {};
}

namespace {

// A JPEG file that does not reach its end-of-image marker is refused (libjpeg would decode it with grey rows), and a
// PNG file cut short (see png_complete).
// Only JPEG and PNG files are read whole for it (an environment map of another format can be hundreds of megabytes).
void check_complete(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char magic[8] = {};
  in.read(reinterpret_cast<char*>(magic), sizeof magic);
  if (truncation(magic, static_cast<size_t>(in.gcount())).empty()) return;  // whole, or neither JPEG nor PNG
  in.clear();
  in.seekg(0);
  const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (const std::string what = truncation(bytes.data(), bytes.size()); !what.empty())
    throw std::runtime_error("cannot read " + file_name(path) + ": it is " + what);
}

// An EXR file whose header declares more than it holds is refused before OpenEXR reads it (exr_attributes_problem).
void check_exr_header(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return;  // OpenImageIO says why it cannot be read
  const size_t size = static_cast<size_t>(in.tellg());
  unsigned char magic[4] = {};
  if (size < 4 || !in.seekg(0).read(reinterpret_cast<char*>(magic), 4) || std::memcmp(magic, kExrMagic, 4) != 0) return;
  const std::string problem = exr_attributes_problem(size, [&](size_t offset, size_t n, unsigned char* out) {
    in.clear();
    return static_cast<bool>(in.seekg(static_cast<std::streamoff>(offset))
                                 .read(reinterpret_cast<char*>(out), static_cast<std::streamsize>(n)));
  });
  if (!problem.empty()) throw std::runtime_error("cannot read " + file_name(path) + ": " + problem);
}

// The pixels of an open image as `channels` floats per texel, texels `stride` floats apart (see read_image).
void read_pixels(OIIO::ImageInput& in, const std::string& path, int channels, size_t stride, float* pixels) {
  const OIIO::ImageSpec& spec = in.spec();
  const size_t texels = static_cast<size_t>(spec.width) * static_cast<size_t>(spec.height);
  const int stored = spec.nchannels;
  const OIIO::stride_t xstride = static_cast<OIIO::stride_t>(stride * sizeof(float));
  bool ok;
  if (stored < 3 && channels >= 3) {
    // Grey (and alpha): the grey read into the first channel of each texel and repeated over the colour channels,
    // the alpha into the fourth when asked for.
    ok = in.read_image(0, 0, 0, 1, OIIO::TypeDesc::FLOAT, pixels, xstride);
    if (ok && stored == 2 && channels >= 4) ok = in.read_image(0, 0, 1, 2, OIIO::TypeDesc::FLOAT, pixels + 3, xstride);
    for (size_t i = 0; ok && i < texels; ++i)
      for (int c = 1; c < 3; ++c) pixels[i * stride + c] = pixels[i * stride];
  } else {
    ok = in.read_image(0, 0, 0, std::min(stored, channels), OIIO::TypeDesc::FLOAT, pixels, xstride);
  }
  if (!ok) throw std::runtime_error("cannot read " + file_name(path) + ": " + scrub(in.geterror(), path));
  in.close();
}

}  // namespace

ImageData read_image(const std::string& path, int channels, size_t max_texels, int max_width) {
  check_complete(path);
  auto in = open_checked(path, max_texels, max_width);
  ImageData img;
  img.width = in->spec().width;
  img.height = in->spec().height;
  img.channels = channels > 0 ? channels : in->spec().nchannels;
  img.pixels.resize(static_cast<size_t>(img.width) * static_cast<size_t>(img.height) * img.channels);
  read_pixels(*in, path, img.channels, static_cast<size_t>(img.channels), img.pixels.data());
  return img;
}

void read_image_into(const std::string& path, int channels, size_t stride, size_t max_texels, int max_width,
                     const std::function<float*(int width, int height)>& place) {
  if (channels < 1 || stride < static_cast<size_t>(channels))
    throw std::invalid_argument("read_image_into: a texel's stride is smaller than its channels");
  check_complete(path);
  auto in = open_checked(path, max_texels, max_width);
  read_pixels(*in, path, channels, stride, place(in->spec().width, in->spec().height));
}

std::unique_ptr<OIIO::ImageInput> open_image_input(const std::string& name, const OIIO::ImageSpec* config) {
  if (!config || !config->find_attribute("oiio:ioproxy")) check_exr_header(name);  // `name` is a file
  static std::mutex opening;
  std::lock_guard<std::mutex> lock(opening);
  return OIIO::ImageInput::open(name, config);
}

}  // namespace tessera
