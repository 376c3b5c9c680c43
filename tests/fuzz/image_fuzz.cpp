// Fuzz target: image files as textures and environment maps reach the renderer (renderer/image_io.h): the JPEG
// header and completeness checks on bytes in memory (as the glTF loader calls them), read_image_header on a file
// (libjpeg for JPEG, OpenImageIO for the rest), then, for an image within small limits, read_image's pixels. Their
// contract: a file they cannot read is a std::runtime_error naming it; any other exception, a crash or a sanitizer
// report is a finding.
#include <cstddef>
#include <cstdint>
#include <stdexcept>

#include "renderer/image_io.h"
#include "tests/fuzz/fuzz_files.h"

namespace {

constexpr size_t kMaxTexels = 64 * 64;
constexpr int kMaxWidth = 256;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tessera::jpeg_header(data, size);
  tessera::jpeg_complete(data, size);
  // The name's extension is a guess OpenImageIO corrects from the bytes, as for a texture named wrongly.
  const std::string path = tessera::fuzz::write_input("image.png", data, size).string();
  try {
    tessera::read_image_header(path, kMaxTexels, kMaxWidth);
    tessera::read_image(path, 4, kMaxTexels, kMaxWidth);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
