#include "server/files/job_files.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <system_error>

#include "renderer/aov.h"
#include "renderer/byte_fields.h"
#include "renderer/frames.h"
#include "server/base/file_io.h"
#include "server/base/job_id.h"

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

[[noreturn]] void write_failed(const char* name, int error) {
  throw std::system_error(error, std::generic_category(), std::string("cannot write ") + name);
}

// A file opened once: its entity tag from the same open file (inode, size, modification time), so that a version
// renamed over meanwhile is neither read nor named.
class OpenFile final : public FileReader {
 public:
  OpenFile(int fd, uint64_t size, std::string etag) : fd_(fd), size_(size), etag_(std::move(etag)) {}
  ~OpenFile() override { ::close(fd_); }
  OpenFile(const OpenFile&) = delete;
  OpenFile& operator=(const OpenFile&) = delete;

  uint64_t size() const override { return size_; }
  const std::string& etag() const override { return etag_; }
  size_t read(uint64_t offset, char* out, size_t length) override {
    size_t done = 0;
    while (done < length) {
      const ssize_t n = ::pread(fd_, out + done, length - done, static_cast<off_t>(offset + done));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      done += static_cast<size_t>(n);
    }
    return done;
  }

 private:
  int fd_;
  uint64_t size_;
  std::string etag_;
};

}  // namespace

namespace {

class BytesReader final : public FileReader {
 public:
  explicit BytesReader(std::string bytes) : bytes_(std::move(bytes)) {
    char etag[48];
    std::snprintf(etag, sizeof etag, "\"b%016llx-%zx\"", static_cast<unsigned long long>(tessera::fnv1a64(bytes_)),
                  bytes_.size());
    etag_ = etag;
  }
  uint64_t size() const override { return bytes_.size(); }
  const std::string& etag() const override { return etag_; }
  size_t read(uint64_t offset, char* out, size_t length) override {
    if (offset >= bytes_.size()) return 0;
    const size_t n = std::min<uint64_t>(length, bytes_.size() - offset);
    std::copy_n(bytes_.data() + offset, n, out);
    return n;
  }

 private:
  std::string bytes_, etag_;
};

}  // namespace

std::unique_ptr<FileReader> bytes_reader(std::string bytes) {
  return std::make_unique<BytesReader>(std::move(bytes));
}

namespace {

// aov.<name>.png for each pass of the table, aov.<index>.png for the room beyond it: fixed names, never a client's.
const std::array<std::string, kMaxPassFiles>& pass_file_names() {
  static const std::array<std::string, kMaxPassFiles> names = [] {
    std::array<std::string, kMaxPassFiles> n;
    const std::vector<AovInfo>& table = aov_table();
    for (size_t i = 0; i < n.size(); ++i)
      n[i] = "aov." + (i < table.size() ? std::string(table[i].name) : std::to_string(i)) + ".png";
    return n;
  }();
  return names;
}

}  // namespace

std::optional<JobFile> pass_file(std::string_view name) {
  const std::vector<AovInfo>& table = aov_table();
  for (size_t i = 0; i < table.size() && i < static_cast<size_t>(kMaxPassFiles); ++i)
    if (table[i].name == name) return pass_file(static_cast<int>(i));
  return std::nullopt;
}

const char* job_file_name(JobFile f) {
  const int pass = static_cast<int>(f) - static_cast<int>(JobFile::kFirstPassPng);
  if (pass >= 0 && pass < kMaxPassFiles) return pass_file_names()[static_cast<size_t>(pass)].c_str();
  switch (f) {
    case JobFile::kPreviewPng:
      return "preview.png";
    case JobFile::kResultPng:
      return "result.png";
    case JobFile::kResultExr:
      return "result.exr";
    case JobFile::kCheckpoint:
      return "checkpoint.bin";
    case JobFile::kLog:
      return "log.txt";
    case JobFile::kFirstPassPng:
      break;
  }
  return "preview.png";
}

JobFile result_file(ImageFormat format) {
  return format == ImageFormat::kPng ? JobFile::kResultPng : JobFile::kResultExr;
}

const char* job_file_media_type(JobFile f) {
  if (f == JobFile::kCheckpoint) return "application/octet-stream";
  if (f == JobFile::kLog) return "text/plain; charset=utf-8";
  return f == JobFile::kResultExr ? "image/x-exr" : "image/png";
}

DirectoryJobFiles::DirectoryJobFiles(fs::path data_dir) : root_(std::move(data_dir) / "jobs") {
  fs::create_directories(root_);
}

void DirectoryJobFiles::prepare(const std::string& id) const {
  std::error_code ec;
  fs::create_directories(dir(id), ec);
}

fs::path DirectoryJobFiles::dir(const std::string& id) const {
  if (!is_valid_job_id(id)) throw std::invalid_argument("not a job id");
  return root_ / id;
}

fs::path DirectoryJobFiles::path(const std::string& id, JobFile f) const {
  return dir(id) / job_file_name(f);
}

void DirectoryJobFiles::write(const std::string& id, JobFile f, std::string_view bytes) const {
  publish_path(path(id, f), job_file_name(f), bytes);
}

void DirectoryJobFiles::publish_path(const fs::path& final_path, const char* name, std::string_view bytes) const {
  // The folder is made when the job starts rendering; if it is gone, the job was deleted: write nothing.
  if (!fs::is_directory(final_path.parent_path()))
    throw std::runtime_error("job " + final_path.parent_path().filename().string() + " has no folder (deleted)");
  // "result.tmp-<pid>-<n>.exr": unique per writer, and the extension still names the format.
  const fs::path temp =
      final_path.parent_path() / (final_path.stem().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                                  std::to_string(g_temp_counter.fetch_add(1)) + final_path.extension().string());
  try {
    if (int error = write_file_synced(temp.string(), bytes); error != 0) write_failed(name, error);
    fs::rename(temp, final_path);
  } catch (...) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    throw;
  }
  fsync_dir(final_path.parent_path());
}

fs::path DirectoryJobFiles::staged_path(const std::string& id, JobFile f, int64_t epoch) const {
  const fs::path final_path = path(id, f);
  return final_path.parent_path() /
         (final_path.stem().string() + ".e" + std::to_string(epoch) + final_path.extension().string());
}

void DirectoryJobFiles::stage(const std::string& id, JobFile f, int64_t epoch, std::string_view bytes) const {
  publish_path(staged_path(id, f, epoch), job_file_name(f), bytes);
}

bool DirectoryJobFiles::publish_staged(const std::string& id, JobFile f, int64_t epoch) const {
  std::error_code ec;
  fs::rename(staged_path(id, f, epoch), path(id, f), ec);
  if (ec) return false;  // none staged (published already, or the job deleted)
  fsync_dir(dir(id));
  return true;
}

void DirectoryJobFiles::discard_staged(const std::string& id, JobFile f, int64_t epoch) const {
  std::error_code ignored;
  fs::remove(staged_path(id, f, epoch), ignored);
}

std::unique_ptr<FileReader> DirectoryJobFiles::open(const std::string& id, JobFile f) const {
  return open_path(path(id, f));
}

void DirectoryJobFiles::write_frame(const std::string& id, JobFile f, int64_t frame, int width,
                                    std::string_view bytes) const {
  publish_path(frame_path(path(id, f), frame, width), job_file_name(f), bytes);
}

std::unique_ptr<FileReader> DirectoryJobFiles::open_frame(const std::string& id, JobFile f, int64_t frame,
                                                          int width) const {
  return open_path(frame_path(path(id, f), frame, width));
}

void DirectoryJobFiles::remove_frames(const std::string& id) const {
  // A frame file is a result file's name with a frame number before its extension (frame_path): result.0012.exr.
  auto is_frame_of = [](const std::string& name, const fs::path& result) {
    const std::string stem = result.stem().string() + ".", ext = result.extension().string();
    if (name.size() <= stem.size() + ext.size() || !name.starts_with(stem) || !name.ends_with(ext)) return false;
    const std::string number = name.substr(stem.size(), name.size() - stem.size() - ext.size());
    return number.find_first_not_of("-0123456789") == std::string::npos;
  };
  std::error_code ec;
  for (fs::directory_iterator it(dir(id), ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (std::any_of(kResultFiles.begin(), kResultFiles.end(),
                    [&](JobFile f) { return is_frame_of(name, job_file_name(f)); })) {
      std::error_code ignored;
      fs::remove(it->path(), ignored);
    }
  }
}

std::unique_ptr<FileReader> DirectoryJobFiles::open_path(const fs::path& file) const {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return nullptr;
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    ::close(fd);
    return nullptr;
  }
  char etag[96];
  std::snprintf(etag, sizeof etag, "\"%llx-%llx-%llx\"", static_cast<unsigned long long>(st.st_ino),
                static_cast<unsigned long long>(st.st_size),
                static_cast<unsigned long long>(st.st_mtim.tv_sec) * 1000000000ull +
                    static_cast<unsigned long long>(st.st_mtim.tv_nsec));
  return std::make_unique<OpenFile>(fd, static_cast<uint64_t>(st.st_size), etag);
}

std::optional<std::string> DirectoryJobFiles::read(const std::string& id, JobFile f) const {
  std::ifstream in(path(id, f), std::ios::binary);
  if (!in) return std::nullopt;
  std::ostringstream ss;
  ss << in.rdbuf();
  return std::move(ss).str();
}

namespace {

// The file name of part `part` of job file `f`: "log.txt" and "n1" give "log.n1.txt".
std::string part_file_name(JobFile f, const std::string& part) {
  const std::string name = job_file_name(f);
  const size_t dot = name.rfind('.');
  const bool plain = !part.empty() && part.size() <= 64 && std::all_of(part.begin(), part.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' || c == '_';
  });
  char hashed[24];
  std::snprintf(hashed, sizeof hashed, "h%016llx", static_cast<unsigned long long>(tessera::fnv1a64(part)));
  return name.substr(0, dot) + "." + (plain ? part : std::string(hashed)) + name.substr(dot);
}

}  // namespace

void DirectoryJobFiles::update(const std::string& id, JobFile f, const std::function<std::string(std::string)>& change,
                               const std::string& part) const {
  static std::mutex updating;
  std::lock_guard lock(updating);
  if (part.empty()) return write(id, f, change(read(id, f).value_or("")));
  const fs::path file = dir(id) / part_file_name(f, part);
  std::optional<std::string> now;
  if (std::ifstream in(file, std::ios::binary); in) {
    std::ostringstream ss;
    ss << in.rdbuf();
    now = std::move(ss).str();
  }
  const std::string bytes = change(now.value_or(""));
  const std::string name = file.filename().string();
  publish_path(file, name.c_str(), bytes);
}

std::vector<std::string> DirectoryJobFiles::read_parts(const std::string& id, JobFile f) const {
  std::vector<std::string> out;
  const std::string name = job_file_name(f);
  const std::string stem = name.substr(0, name.rfind('.') + 1), extension = name.substr(name.rfind('.'));
  std::error_code ec;
  for (fs::directory_iterator it(dir(id), ec), end; !ec && it != end; it.increment(ec)) {
    const std::string entry = it->path().filename().string();
    const bool part = entry.size() > stem.size() + extension.size() && entry.starts_with(stem) &&
                      entry.ends_with(extension) && entry.find(".tmp-") == std::string::npos;
    if (entry != name && !part) continue;
    std::ifstream in(it->path(), std::ios::binary);
    if (!in) continue;  // removed meanwhile
    std::ostringstream ss;
    ss << in.rdbuf();
    out.push_back(std::move(ss).str());
  }
  return out;
}

void DirectoryJobFiles::remove(const std::string& id) const {
  std::error_code ignored;
  fs::remove_all(dir(id), ignored);
}

void DirectoryJobFiles::remove(const std::string& id, JobFile f) const {
  std::error_code ignored;
  fs::remove(path(id, f), ignored);
}

fs::path DirectoryJobFiles::unit_path(const std::string& id, int unit, int64_t epoch) const {
  return dir(id) / ("unit-" + std::to_string(unit) + ".e" + std::to_string(epoch) + ".ckpt");
}

void DirectoryJobFiles::write_unit(const std::string& id, int unit, int64_t epoch, std::string_view bytes) const {
  const fs::path p = unit_path(id, unit, epoch);
  const std::string name = p.filename().string();
  publish_path(p, name.c_str(), bytes);
}

std::optional<std::string> DirectoryJobFiles::read_unit(const std::string& id, int unit, int64_t epoch) const {
  std::ifstream in(unit_path(id, unit, epoch), std::ios::binary);
  if (!in) return std::nullopt;
  std::ostringstream ss;
  ss << in.rdbuf();
  return std::move(ss).str();
}

void DirectoryJobFiles::remove_units(const std::string& id) const {
  std::error_code ec;
  for (fs::directory_iterator it(dir(id), ec), end; !ec && it != end; it.increment(ec))
    if (it->path().filename().string().starts_with("unit-")) {
      std::error_code ignored;
      fs::remove(it->path(), ignored);
    }
}

}  // namespace tessera::server
