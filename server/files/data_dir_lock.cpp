#include "server/files/data_dir_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>

namespace tessera::server {

std::variant<DataDirLock, std::string> DataDirLock::acquire(const std::filesystem::path& data_dir,
                                                            const std::string& node) {
  const std::filesystem::path file = data_dir / (node.empty() ? std::string(kFileName) : "tesserad-" + node + ".lock");
  const int fd = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) return "cannot open " + file.string() + ": " + std::strerror(errno);
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int error = errno;
    ::close(fd);
    if (error != EWOULDBLOCK) return "cannot lock " + file.string() + ": " + std::strerror(error);
    // The holder writes its id right after it takes the lock: a moment's race may find it empty.
    std::string holder;
    std::ifstream(file) >> holder;
    if (!node.empty())
      return "the node name " + node + " is in use by another tesserad on the data directory " + data_dir.string() +
             (holder.empty() ? std::string() : " (process " + holder + ")") + "; it holds " + file.string() +
             ". Stop it, or give this one another --node";
    return "the data directory " + data_dir.string() + " is in use by another tesserad" +
           (holder.empty() ? std::string() : " (process " + holder + ")") + "; it holds " + file.string() +
           ". Stop it, or give this one another --data-dir";
  }
  // Should this fail, the lock holds all the same: only the message of a second daemon would lack the id.
  const std::string pid = std::to_string(::getpid()) + "\n";
  const bool written =
      ::ftruncate(fd, 0) == 0 && ::pwrite(fd, pid.data(), pid.size(), 0) == static_cast<ssize_t>(pid.size());
  (void)written;
  return DataDirLock(fd);
}

DataDirLock::DataDirLock(DataDirLock&& other) noexcept : fd_(other.fd_) {
  other.fd_ = -1;
}

DataDirLock::~DataDirLock() {
  if (fd_ >= 0) ::close(fd_);
}

}  // namespace tessera::server
