#include "server/job_log.h"

#include <algorithm>
#include <exception>

#include "server/log.h"
#include "server/time_format.h"

namespace tessera::server {

namespace {

constexpr const char* kOmitted = "[earlier lines left out: the log keeps its first and its latest lines]\n";

}  // namespace

std::string append_bounded(std::string log, const std::string& line, size_t max_bytes, size_t head_bytes) {
  log += line;
  if (log.empty() || log.back() != '\n') log += '\n';
  if (log.size() <= max_bytes) return log;
  // The head: the lines before the marker of an earlier cut, or the whole lines within head_bytes.
  size_t head_end;
  const std::string marker = kOmitted;
  if (const size_t at = log.find(marker); at != std::string::npos) {
    head_end = at;
  } else {
    head_end = log.rfind('\n', head_bytes > 0 ? head_bytes - 1 : 0);
    head_end = head_end == std::string::npos ? 0 : head_end + 1;
  }
  std::string head = log.substr(0, head_end) + marker;
  std::string tail = log.substr(log.find(marker, head_end) == head_end ? head_end + marker.size() : head_end);
  // Drop the oldest lines of the rest until it fits (a single line longer than the room left is cut to it).
  while (!tail.empty() && head.size() + tail.size() > max_bytes) {
    const size_t next = tail.find('\n');
    if (next == std::string::npos || next + 1 >= tail.size()) {
      tail = tail.substr(tail.size() - std::min(tail.size(), max_bytes > head.size() ? max_bytes - head.size() : 0));
      break;
    }
    tail.erase(0, next + 1);
  }
  return head + tail;
}

void JobLog::add(const std::string& id, const std::string& line) const {
  try {
    std::lock_guard lock(mutex_);
    std::string text = files_.read(id, JobFile::kLog).value_or("");
    files_.write(id, JobFile::kLog, append_bounded(std::move(text), rfc3339_ms(now_ms()) + "  " + line));
  } catch (const std::exception& e) {
    log(LogLevel::kDebug, "cannot write the job's log", {{"job", id}, {"error", e.what()}});
  }
}

}  // namespace tessera::server
