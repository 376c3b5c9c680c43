// One daemon per data directory (per node name, when the jobs are in a shared store): an exclusive flock(2) on
// <data>/tesserad.lock (tesserad-NODE.lock), held for the life of the process (the
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
  // With `node` (a daemon whose jobs are in a shared store), the lock is that node's (tesserad-NODE.lock): daemons
  // of other names may share the directory (a volume every node mounts), one of the same name may not.
  static std::variant<DataDirLock, std::string> acquire(const std::filesystem::path& data_dir,
                                                        const std::string& node = "");
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
