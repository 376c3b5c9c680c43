// Image input through OpenImageIO, and the checks made of image data before it is decoded. Images are written by
// the output pipeline (renderer/output.h).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace tessera {

struct ImageData {
  int width = 0, height = 0, channels = 0;
  std::vector<float> pixels;  // as stored, converted to float (PNG: 0..1 sRGB-encoded values)
};
// Reads any image OpenImageIO reads; throws with OpenImageIO's message on failure. `channels` > 0 reads that many
// channels straight into place: the first ones stored, a grey image's one repeated, missing ones 0 (an RGB read of
// an RGBA file never holds the alpha channel in memory). `max_texels` > 0 and `max_width` > 0 refuse larger images
// from their header, before any pixel memory is allocated.
ImageData read_image(const std::string& path, int channels = 0, size_t max_texels = 0, int max_width = 0);
// The same into memory of the caller's: once the header is checked, place(width, height) returns where texel (x, y)
// goes, at offset (y * width + x) * stride floats; `channels` floats of it are written (stride >= channels).
void read_image_into(const std::string& path, int channels, size_t stride, size_t max_texels, int max_width,
                     const std::function<float*(int width, int height)>& place);
struct ImageHeader {
  int width = 0, height = 0, channels = 0;
};
// The same checks as read_image (the file opens, the limits hold) from the header alone: no pixels are read. JPEG
// headers are read with libjpeg itself: OpenImageIO's open decodes a progressive JPEG's every scan.
ImageHeader read_image_header(const std::string& path, size_t max_texels = 0, int max_width = 0);
// The header of JPEG data in memory (libjpeg's, without decoding any scan), or nothing when it is not readable JPEG.
std::optional<ImageHeader> jpeg_header(const unsigned char* bytes, size_t size);
// Whether JPEG data reaches its end-of-image marker. libjpeg (and so OpenImageIO) decodes a file cut short with a
// warning only, the missing rows grey: read_image refuses such a file, and a glTF loader should too.
bool jpeg_complete(const unsigned char* bytes, size_t size);
// Whether PNG data holds each of its chunks whole, up to its IEND chunk (PNG specification, 2nd edition, 5.3 "Chunk
// layout" and 11.2.5 "IEND"). libpng reports data cut short through OpenImageIO 2.4.7's read callback, which loses
// the memory of its message on the way (it longjmps out past a std::string; found by fuzz_gltf and fuzz_image): a
// truncated PNG is refused before it is decoded.
bool png_complete(const unsigned char* bytes, size_t size);
// What is wrong with the header of EXR data whose attributes declare more bytes than the data holds (OpenEXR 3.1
// allocates what they declare before reading it); empty for a sound header, or data of another format. Files are
// checked by open_image_input (renderer/image_input.h) before OpenImageIO opens them.
std::string exr_header_problem(const unsigned char* bytes, size_t size);
// What data of a JPEG or a PNG that ends before its end is ("a truncated JPEG (its data ends before ...)"), for
// messages; empty when the data is whole, or of another format.
std::string truncation(const unsigned char* bytes, size_t size);

}  // namespace tessera
