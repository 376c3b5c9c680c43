// What the fuzz targets share: the readers under test take file names, so an input is written to a file first, in a
// folder of the fuzzing process's own (libFuzzer's -fork and -jobs run several processes side by side).
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

namespace tessera::fuzz {

// The process's folder, made on first use and removed when the process exits normally (a crash leaves it behind, in
// the system's temporary folder).
inline const std::filesystem::path& scratch_dir() {
  static const struct Folder {
    std::filesystem::path path =
        std::filesystem::temp_directory_path() / ("tessera-fuzz-" + std::to_string(::getpid()));
    Folder() { std::filesystem::create_directories(path); }
    ~Folder() {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  } folder;
  return folder.path;
}

// Writes the input to `name` in the scratch folder, replacing the last input's; returns its path.
inline std::filesystem::path write_input(const std::string& name, const uint8_t* data, size_t size) {
  const std::filesystem::path path = scratch_dir() / name;
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path;
}

}  // namespace tessera::fuzz
