// The files of jobs under the data directory: <data>/jobs/<id>/{preview.png,result.png,result.exr,checkpoint.bin}. Paths are only
// ever built from validated job ids and fixed names, so nothing a client sends can reach outside the directory.
// Every file is written beside its final name and renamed over it, so a reader (or a crash) never sees half a file.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::server {

enum class JobFile { kPreviewPng, kResultPng, kResultExr, kCheckpoint };
const char* job_file_name(JobFile f);
const char* job_file_media_type(JobFile f);

class JobFiles {
 public:
  explicit JobFiles(std::filesystem::path data_dir);

  const std::filesystem::path& root() const { return root_; }
  // Throws std::invalid_argument for an id that is not a valid job id.
  std::filesystem::path dir(const std::string& id) const;
  std::filesystem::path path(const std::string& id, JobFile f) const;

  // Writes `bytes` atomically (temp file, fsync, rename). On failure (a full disk: std::system_error with ENOSPC,
  // "cannot write checkpoint.bin") the file's last version stays as it was and no temp file is left.
  void write(const std::string& id, JobFile f, std::string_view bytes) const;
  // Atomically publishes a file written by `writer` to the temp path it is given (which keeps the final extension,
  // for writers that choose the format by it); fsynced before the rename, failing like write().
  void write_with(const std::string& id, JobFile f, const std::function<void(const std::string&)>& writer) const;
  // The file's bytes, or nothing when it does not exist.
  std::optional<std::string> read(const std::string& id, JobFile f) const;
  void remove(const std::string& id) const;
  void remove(const std::string& id, JobFile f) const;

 private:
  void publish(const std::string& id, JobFile f, const std::function<void(const std::string&)>& writer,
               bool writer_synced) const;

  std::filesystem::path root_;
};

}  // namespace tessera::server
