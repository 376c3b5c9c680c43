#include "server/base/file_io.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>

namespace tessera::server {

int write_file_synced(const std::filesystem::path& path, std::string_view bytes) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return errno;
  int error = 0;
  for (size_t done = 0; done < bytes.size() && error == 0;) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      error = n < 0 ? errno : EIO;
    } else {
      done += static_cast<size_t>(n);
    }
  }
  if (error == 0 && ::fsync(fd) != 0) error = errno;
  if (::close(fd) != 0 && error == 0) error = errno;
  return error;
}

bool is_out_of_space(int error) {
  return error == ENOSPC || error == EDQUOT || error == EFBIG;
}

bool is_out_of_space(const std::error_code& ec) {
  // std::filesystem reports errno values in the system category (the generic one on some libraries).
  const bool posix = ec.category() == std::system_category() || ec.category() == std::generic_category();
  return posix && is_out_of_space(ec.value());
}

}  // namespace tessera::server
