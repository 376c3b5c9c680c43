// A job's log, kept with its files (log.txt, JobFiles): what its renders did, one line each, for its owner (GET
// /v1/jobs/{id}/log, `tessera log ID`, the web client's job view): how long loading took, the scene's warnings, each
// pass, how the render ended and why. Bounded: past kMaxLogBytes, the first lines stay (how it started) and the
// oldest of the rest give way to the newest, with one line saying so. Writing it is best effort: a log that cannot be
// written (a full disk, a job deleted meanwhile) never fails the job.
#pragma once

#include <cstddef>
#include <mutex>
#include <string>

#include "server/job_files.h"

namespace tessera::server {

inline constexpr size_t kMaxLogBytes = 64 * 1024;
// The start of a log kept whole when it outgrows kMaxLogBytes.
inline constexpr size_t kLogHeadBytes = 8 * 1024;

// `log` with `line` added (a newline ends it), held to `max_bytes`: whole lines, the first `head_bytes` of them kept,
// then a line saying that lines were left out, then the newest lines that fit.
std::string append_bounded(std::string log, const std::string& line, size_t max_bytes = kMaxLogBytes,
                           size_t head_bytes = kLogHeadBytes);

class JobLog {
 public:
  explicit JobLog(const JobFiles& files) : files_(files) {}
  // Adds "<RFC 3339 time>  <line>" to the job's log; nothing when the job has no place for files (it never started
  // rendering, or was deleted) or the file cannot be written.
  void add(const std::string& id, const std::string& line) const;

 private:
  const JobFiles& files_;
  mutable std::mutex mutex_;  // one read-modify-write at a time
};

}  // namespace tessera::server
