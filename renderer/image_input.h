// The one way the renderer opens an image for reading through OpenImageIO.
#pragma once

#include <OpenImageIO/imageio.h>

#include <memory>
#include <string>

namespace tessera {

// OIIO::ImageInput::open(name, config), serialised across the process. OpenImageIO 2.4 (Debian 12 has 2.4.7) is not
// safe when two threads open JPEG files at once: decoding an embedded ICC profile looks tag names up in tables shared
// by the process with std::unordered_map::operator[], which inserts every name not seen before, so two threads that
// meet new names rehash the same table and crash (later releases look the names up without inserting). Opening reads
// only the header (and, for JPEG, the markers before the first scan), so one lock around it costs little, while
// pixels are still read in parallel through the ImageInputs it returns. Every ImageInput the renderer makes comes
// from here, whatever the format, so that no new reader can forget the lock.
// A file (no "oiio:ioproxy" in `config`) that is EXR is first held to its own size (exr_header_problem,
// renderer/image_io.h): std::runtime_error naming the file and what it declares.
std::unique_ptr<OIIO::ImageInput> open_image_input(const std::string& name, const OIIO::ImageSpec* config = nullptr);

}  // namespace tessera
