#include "server/job_files.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <system_error>

#include "server/job_id.h"

namespace tessera::server {

namespace fs = std::filesystem;

namespace {

std::atomic<uint64_t> g_temp_counter{0};

void fsync_path(const fs::path& p, bool directory) {
  int fd = ::open(p.c_str(), (directory ? O_RDONLY | O_DIRECTORY : O_RDONLY) | O_CLOEXEC);
  if (fd < 0) return;  // best effort: durability, not correctness, depends on it
  ::fsync(fd);
  ::close(fd);
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
    fsync_path(temp, false);
    fs::rename(temp, final_path);
  } catch (...) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    throw;
  }
  fsync_path(final_path.parent_path(), true);
}

void JobFiles::write(const std::string& id, JobFile f, std::string_view bytes) const {
  write_with(id, f, [&](const std::string& temp) {
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) throw std::runtime_error("cannot write " + temp + ": " + std::strerror(errno));
  });
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
