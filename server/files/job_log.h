// A job's log, kept with its files (log.txt, JobFiles): what its renders did, one line each, for its owner (GET
// /v1/jobs/{id}/log, `tessera log ID`, the web client's job view): how long loading took, the scene's warnings, each
// pass, how the render ended and why. Bounded: past kMaxLogBytes, the first lines stay (how it started) and the
// oldest of the rest give way to the newest, with one line saying so. Writing it is best effort: a log that cannot be
// written (a full disk, a job deleted meanwhile) never fails the job.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <utility>

#include "server/files/job_files.h"

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
  // `node`: the name of this daemon among the nodes that share a store, written on each line (several nodes write
  // one job's log when they render its units); empty for a daemon alone.
  explicit JobLog(const JobFiles& files, std::string node = "") : files_(files), node_(std::move(node)) {}
  // Adds "<RFC 3339 time>  <line>" (with a node: "<time>  <node>  <line>") to the job's log; nothing when the job has
  // no place for files (it never started rendering, or was deleted) or the file cannot be written. A node writes its
  // own part of the log (JobFiles::update), each part bounded as the whole is.
  void add(const std::string& id, const std::string& line) const;
  // The job's log: the lines of every node's part in the order of their times (a line's time is its first field;
  // lines of one time keep their part's order), bounded as one part is. Nothing when no part exists.
  static std::optional<std::string> read(const JobFiles& files, const std::string& id);

 private:
  const JobFiles& files_;
  const std::string node_;
};

}  // namespace tessera::server
