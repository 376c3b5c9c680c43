#include "server/files/job_log.h"

#include <algorithm>
#include <exception>
#include <string_view>
#include <tuple>
#include <vector>

#include "server/base/log.h"
#include "server/base/time_format.h"

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
    const std::string stamped = rfc3339_ms(now_ms()) + "  " + (node_.empty() ? "" : node_ + "  ") + line;
    files_.update(
        id, JobFile::kLog, [&](std::string text) { return append_bounded(std::move(text), stamped); }, node_);
  } catch (const std::exception& e) {
    log(LogLevel::kDebug, "cannot write the job's log", {{"job", id}, {"error", e.what()}});
  }
}

std::optional<std::string> JobLog::read(const JobFiles& files, const std::string& id) {
  std::vector<std::string> parts = files.read_parts(id, JobFile::kLog);
  if (parts.empty()) return std::nullopt;
  if (parts.size() == 1) return std::move(parts[0]);
  // (time, part, line number) orders the lines; a line that does not start with a time (the marker of lines left
  // out) takes the time of the line before it in its part, so it stays where it was.
  struct Line {
    std::string_view time, text;
    size_t part, index;
  };
  std::vector<Line> lines;
  for (size_t p = 0; p < parts.size(); ++p) {
    std::string_view rest = parts[p], time;
    for (size_t i = 0; !rest.empty(); ++i) {
      const size_t end = rest.find('\n');
      const std::string_view text = rest.substr(0, end == std::string_view::npos ? rest.size() : end + 1);
      rest.remove_prefix(text.size());
      if (!text.empty() && text[0] >= '0' && text[0] <= '9') time = text.substr(0, text.find(' '));
      lines.push_back({time, text, p, i});
    }
  }
  std::sort(lines.begin(), lines.end(), [](const Line& a, const Line& b) {
    return std::tie(a.time, a.part, a.index) < std::tie(b.time, b.part, b.index);
  });
  std::string merged;
  for (const Line& l : lines) {
    merged += l.text;
    if (merged.back() != '\n') merged += '\n';
  }
  if (merged.size() <= kMaxLogBytes) return merged;
  // Bounded as one part is: the last line appended to the rest.
  merged.pop_back();
  const size_t last = merged.rfind('\n');
  return last == std::string::npos ? append_bounded("", merged)
                                   : append_bounded(merged.substr(0, last + 1), merged.substr(last + 1));
}

}  // namespace tessera::server
