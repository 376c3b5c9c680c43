// One daemon per data directory: an exclusive flock(2) on <data>/tesserad.lock, held for the life of the process (the
// kernel drops it when the process ends, however it ends, so a crash leaves nothing stale behind). The file holds the
// holder's process id, which a second daemon names when it refuses to start. Two daemons on one directory would
// each take the other's running jobs for orphans and render them twice.
#pragma once

#include <filesystem>
#include <string>
#include <variant>

namespace tessera::server {

class DataDirLock {
 public:
  // The lock, or why not: the message names the directory and, when another process holds it, that process's id.
  static std::variant<DataDirLock, std::string> acquire(const std::filesystem::path& data_dir);
  ~DataDirLock();
  DataDirLock(DataDirLock&& other) noexcept;
  DataDirLock& operator=(DataDirLock&&) = delete;
  DataDirLock(const DataDirLock&) = delete;
  DataDirLock& operator=(const DataDirLock&) = delete;

  static constexpr const char* kFileName = "tesserad.lock";

 private:
  explicit DataDirLock(int fd) : fd_(fd) {}
  int fd_ = -1;
};

}  // namespace tessera::server
