#include "server/job_files.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <system_error>

#include "server/file_io.h"
#include "server/job_id.h"

namespace tessera::server {

namespace fs = std::filesystem;

namespace {

std::atomic<uint64_t> g_temp_counter{0};

// The directory's entry of a renamed file: best effort, durability (not correctness) depends on it.
void fsync_dir(const fs::path& p) {
  int fd = ::open(p.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

// A file just written, before it is renamed over the last good version: a filesystem that allocates late (NFS,
// XFS, btrfs, a quota) reports ENOSPC or EIO only here, and a file whose data never reached the disk must not replace
// a good one. 0 or the errno.
int fsync_file(const fs::path& p) {
  int fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return errno;
  const int error = ::fsync(fd) == 0 ? 0 : errno;
  ::close(fd);
  return error;
}

[[noreturn]] void write_failed(JobFile f, int error) {
  throw std::system_error(error, std::generic_category(), std::string("cannot write ") + job_file_name(f));
}

}  // namespace

const char* job_file_name(JobFile f) {
  switch (f) {
    case JobFile::kPreviewPng:
      return "preview.png";
    case JobFile::kResultPng:
      return "result.png";
    case JobFile::kResultExr:
      return "result.exr";
    case JobFile::kCheckpoint:
      return "checkpoint.bin";
  }
  return "preview.png";
}

const char* job_file_media_type(JobFile f) {
  if (f == JobFile::kCheckpoint) return "application/octet-stream";
  return f == JobFile::kResultExr ? "image/x-exr" : "image/png";
}

JobFiles::JobFiles(fs::path data_dir) : root_(std::move(data_dir) / "jobs") {
  fs::create_directories(root_);
}

fs::path JobFiles::dir(const std::string& id) const {
  if (!is_valid_job_id(id)) throw std::invalid_argument("not a job id");
  return root_ / id;
}

fs::path JobFiles::path(const std::string& id, JobFile f) const {
  return dir(id) / job_file_name(f);
}

void JobFiles::write_with(const std::string& id, JobFile f,
                          const std::function<void(const std::string&)>& writer) const {
  publish(id, f, writer, false);
}

void JobFiles::write(const std::string& id, JobFile f, std::string_view bytes) const {
  publish(
      id, f,
      [&](const std::string& temp) {
        if (int error = write_file_synced(temp, bytes); error != 0) write_failed(f, error);
      },
      true);
}

void JobFiles::publish(const std::string& id, JobFile f, const std::function<void(const std::string&)>& writer,
                       bool writer_synced) const {
  const fs::path final_path = path(id, f);
  // The folder is made when the job starts rendering; if it is gone, the job was deleted: write nothing.
  if (!fs::is_directory(final_path.parent_path()))
    throw std::runtime_error("job " + id + " has no folder (deleted)");
  // "result.tmp-<pid>-<n>.exr": unique per writer, and the extension still names the format.
  const fs::path temp =
      final_path.parent_path() / (final_path.stem().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                                  std::to_string(g_temp_counter.fetch_add(1)) + final_path.extension().string());
  try {
    writer(temp.string());
    if (!writer_synced)
      if (int error = fsync_file(temp); error != 0) write_failed(f, error);
    fs::rename(temp, final_path);
  } catch (...) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    throw;
  }
  fsync_dir(final_path.parent_path());
}

std::optional<std::string> JobFiles::read(const std::string& id, JobFile f) const {
  std::ifstream in(path(id, f), std::ios::binary);
  if (!in) return std::nullopt;
  std::ostringstream ss;
  ss << in.rdbuf();
  return std::move(ss).str();
}

void JobFiles::remove(const std::string& id) const {
  std::error_code ignored;
  fs::remove_all(dir(id), ignored);
}

}  // namespace tessera::server

namespace tessera::server {

void JobFiles::remove(const std::string& id, JobFile f) const {
  std::error_code ignored;
  fs::remove(path(id, f), ignored);
}

}  // namespace tessera::server
