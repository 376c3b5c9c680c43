// Writing a whole file with plain POSIX calls, so that every failure reports its errno (a stream only says that
// something failed), and telling a disk that is out of room from one that is broken.
#pragma once

#include <filesystem>
#include <string_view>
#include <system_error>

namespace tessera::server {

// Writes `bytes` to `path` (created, or truncated) and fsyncs it: a filesystem that allocates late (NFS, XFS, btrfs,
// a quota) reports ENOSPC only at the fsync or the close. 0, or the errno of the call that failed.
int write_file_synced(const std::filesystem::path& path, std::string_view bytes);

// A write failed for want of room (ENOSPC a full disk, EDQUOT a quota, EFBIG a file-size limit), which freeing space
// cures, as opposed to a fault of the disk or the daemon.
bool is_out_of_space(int error);
bool is_out_of_space(const std::error_code& ec);

}  // namespace tessera::server
