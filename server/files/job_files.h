// The files of jobs (preview, results, checkpoint, log): an interface, so that every node of a daemon can reach them
// wherever they are kept, and its implementation in the data directory, <data>/jobs/<id>/{preview.png,result.png,
// result.exr,checkpoint.bin,log.txt}. Paths are only ever built from validated job ids and fixed names, so nothing a
// client sends can reach outside the directory. Every file is written beside its final name and renamed over it, so a
// reader (or a crash) never sees half a file.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "renderer/output.h"

namespace tessera::server {

// The render passes' PNGs (OutputPipeline::publish_passes) follow the fixed files: pass i of aov.h's table is
// pass_file(i), aov.<name>.png, with room for kMaxPassFiles passes.
enum class JobFile : int { kPreviewPng, kResultPng, kResultExr, kCheckpoint, kLog, kFirstPassPng };
inline constexpr int kMaxPassFiles = 32;
constexpr JobFile pass_file(int index) {
  return static_cast<JobFile>(static_cast<int>(JobFile::kFirstPassPng) + index);
}
// The PNG of the pass named `name`, or nothing for a name that is not a pass.
std::optional<JobFile> pass_file(std::string_view name);
const char* job_file_name(JobFile f);
const char* job_file_media_type(JobFile f);
// The file each output format is published as (OutputPipeline), and all the files a run's end publishes: the
// results and the passes' PNGs.
JobFile result_file(ImageFormat format);
inline constexpr auto kResultFiles = [] {
  std::array<JobFile, 2 + kMaxPassFiles> files{JobFile::kResultPng, JobFile::kResultExr};
  for (int i = 0; i < kMaxPassFiles; ++i) files[static_cast<size_t>(2 + i)] = pass_file(i);
  return files;
}();

// One version of a stored file, opened for reading in pieces (an HTTP answer streams it): a version written
// meanwhile does not mix into it.
class FileReader {
 public:
  virtual ~FileReader() = default;
  virtual uint64_t size() const = 0;
  // The identity of this version, quoted as an HTTP entity tag: a file written again gets another.
  virtual const std::string& etag() const = 0;
  // Up to `length` bytes from `offset`; fewer only at the end of the file, 0 past it or on a read error.
  virtual size_t read(uint64_t offset, char* out, size_t length) = 0;
};

// Bytes in memory read as a file (a job's log, merged from its parts); its entity tag is a hash of the bytes.
std::unique_ptr<FileReader> bytes_reader(std::string bytes);

class JobFiles {
 public:
  virtual ~JobFiles() = default;

  // Makes the job's place for files, when it starts rendering. Writes never make it, so a render still winding down
  // cannot bring back the files of a job deleted meanwhile: they throw instead.
  virtual void prepare(const std::string& id) const = 0;
  // Writes `bytes` atomically: on failure (a full disk: std::system_error with ENOSPC, "cannot write
  // checkpoint.bin") the file's last version stays as it was and nothing half-written is left.
  virtual void write(const std::string& id, JobFile f, std::string_view bytes) const = 0;
  // Outputs fenced by the end of the run that made them (a result file): `bytes` are written as write() writes them,
  // under a name of the run's epoch beside the final one, where no reader looks. publish_staged() renames it over the
  // final name once the store has taken the run's end; discard_staged() removes it when the store refused that end.
  // publish_staged() is false (and changes nothing) when no such file exists: already published, or never staged.
  virtual void stage(const std::string& id, JobFile f, int64_t epoch, std::string_view bytes) const = 0;
  virtual bool publish_staged(const std::string& id, JobFile f, int64_t epoch) const = 0;
  virtual void discard_staged(const std::string& id, JobFile f, int64_t epoch) const = 0;
  // The file's bytes, or nothing when it does not exist.
  virtual std::optional<std::string> read(const std::string& id, JobFile f) const = 0;
  // Replaces the file with change(its bytes, empty when it does not exist), written as write() writes, with no other
  // update of it in between: this process's updates take turns. With a `part`, it is this process's part of the file
  // (`log.<part>.txt` beside `log.txt`) that changes. Each file or part has one writing process: the nodes that share
  // a data directory each update their own part (every node rendering a unit of a job adds to its log), so no node
  // ever waits on another; a lock across nodes would stall them all behind one that froze while it held the lock.
  virtual void update(const std::string& id, JobFile f, const std::function<std::string(std::string)>& change,
                      const std::string& part = "") const = 0;
  // The file's bytes, then each of its parts' (update()), in no particular order; empty when none exists.
  virtual std::vector<std::string> read_parts(const std::string& id, JobFile f) const = 0;
  // The file's current version; null when it does not exist.
  virtual std::unique_ptr<FileReader> open(const std::string& id, JobFile f) const = 0;
  // Every file of the job, and its place.
  virtual void remove(const std::string& id) const = 0;
  virtual void remove(const std::string& id, JobFile f) const = 0;

  // The checkpoint of one work unit of a job (work_units.h), named by the epoch of the run that writes it: a run
  // writes only its own epoch's file, and the store records which one is the unit's (JobStore::update_progress), so a
  // node that lost its lease cannot overwrite the checkpoint or film of the run that took the unit over. Written as
  // write() writes; nothing when it does not exist.
  virtual void write_unit(const std::string& id, int unit, int64_t epoch, std::string_view bytes) const = 0;
  virtual std::optional<std::string> read_unit(const std::string& id, int unit, int64_t epoch) const = 0;
  // Every unit file of the job (a job requeued from scratch, or merged).
  virtual void remove_units(const std::string& id) const = 0;

  // The file `f` of frame `frame` of a frame range (renderer/frames.h: frame_path), its number written with `width`
  // characters: result.0012.exr. Written as write() writes, and not fenced by a run's epoch: every run of a frame
  // renders the same bits (the job's seed, the frame's time), so a run that lost its lease writes what its successor
  // writes. Nothing when it does not exist.
  virtual void write_frame(const std::string& id, JobFile f, int64_t frame, int width,
                           std::string_view bytes) const = 0;
  virtual std::unique_ptr<FileReader> open_frame(const std::string& id, JobFile f, int64_t frame, int width) const = 0;
  // Every frame file of the job (a job requeued from scratch).
  virtual void remove_frames(const std::string& id) const = 0;
};

// The files in the data directory (of one machine, or a volume every node mounts).
class DirectoryJobFiles final : public JobFiles {
 public:
  explicit DirectoryJobFiles(std::filesystem::path data_dir);

  const std::filesystem::path& root() const { return root_; }
  // Throws std::invalid_argument for an id that is not a valid job id.
  std::filesystem::path dir(const std::string& id) const;
  std::filesystem::path path(const std::string& id, JobFile f) const;

  void prepare(const std::string& id) const override;
  // Temp file beside the final one, fsync, rename.
  void write(const std::string& id, JobFile f, std::string_view bytes) const override;
  // <data>/jobs/<id>/result.e<epoch>.png (the final name's stem, the epoch, its extension)
  void stage(const std::string& id, JobFile f, int64_t epoch, std::string_view bytes) const override;
  bool publish_staged(const std::string& id, JobFile f, int64_t epoch) const override;
  void discard_staged(const std::string& id, JobFile f, int64_t epoch) const override;
  std::optional<std::string> read(const std::string& id, JobFile f) const override;
  // Throws, as write() does, when the job has no folder. A part's name is `log.<part>.txt` where `part` is made of
  // letters, digits, '-' and '_' (up to 64 of them), else `log.h<hash of part>.txt`.
  void update(const std::string& id, JobFile f, const std::function<std::string(std::string)>& change,
              const std::string& part = "") const override;
  std::vector<std::string> read_parts(const std::string& id, JobFile f) const override;
  std::unique_ptr<FileReader> open(const std::string& id, JobFile f) const override;
  void remove(const std::string& id) const override;
  void remove(const std::string& id, JobFile f) const override;
  // <data>/jobs/<id>/unit-<unit>.e<epoch>.ckpt
  void write_unit(const std::string& id, int unit, int64_t epoch, std::string_view bytes) const override;
  std::optional<std::string> read_unit(const std::string& id, int unit, int64_t epoch) const override;
  void remove_units(const std::string& id) const override;
  // <data>/jobs/<id>/result.<frame>.exr
  void write_frame(const std::string& id, JobFile f, int64_t frame, int width, std::string_view bytes) const override;
  std::unique_ptr<FileReader> open_frame(const std::string& id, JobFile f, int64_t frame, int width) const override;
  void remove_frames(const std::string& id) const override;

 private:
  std::unique_ptr<FileReader> open_path(const std::filesystem::path& path) const;
  // Temp file beside `final_path`, fsync, rename, fsync of the folder; `name` is the file's for messages.
  void publish_path(const std::filesystem::path& final_path, const char* name, std::string_view bytes) const;
  std::filesystem::path unit_path(const std::string& id, int unit, int64_t epoch) const;
  std::filesystem::path staged_path(const std::string& id, JobFile f, int64_t epoch) const;

  std::filesystem::path root_;
};

}  // namespace tessera::server
