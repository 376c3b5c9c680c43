#include "server/base/log.h"

#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>

#include "server/base/time_format.h"

namespace tessera::server {

namespace {
std::atomic<LogLevel> g_level{LogLevel::kInfo};
std::mutex g_mutex;

const char* level_name(LogLevel l) {
  switch (l) {
    case LogLevel::kDebug:
      return "debug";
    case LogLevel::kInfo:
      return "info";
    case LogLevel::kWarn:
      return "warn";
    case LogLevel::kError:
      return "error";
  }
  return "info";
}
}  // namespace

bool parse_log_level(std::string_view name, LogLevel* out) {
  for (LogLevel l : {LogLevel::kDebug, LogLevel::kInfo, LogLevel::kWarn, LogLevel::kError}) {
    if (name == level_name(l)) {
      *out = l;
      return true;
    }
  }
  return false;
}

void set_log_level(LogLevel level) {
  g_level.store(level);
}

bool log_enabled(LogLevel level) {
  return level >= g_level.load();
}

void log(LogLevel level, std::string_view msg, const nlohmann::json& fields) {
  if (!log_enabled(level)) return;
  nlohmann::json line = {{"ts", rfc3339_ms(now_ms())}, {"level", level_name(level)}, {"msg", std::string(msg)}};
  if (fields.is_object())
    for (const auto& [k, v] : fields.items()) line[k] = v;
  // Replace invalid UTF-8 (from an exception message quoting client input) rather than throw while logging.
  const std::string text = line.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
  std::lock_guard lock(g_mutex);
  std::fwrite(text.data(), 1, text.size(), stderr);
  std::fflush(stderr);
}

}  // namespace tessera::server
