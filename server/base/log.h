// Logs: one JSON object a line on stderr, {"ts", "level", "msg", "job"?, ...fields}, so log shippers need no parser.
#pragma once

#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

namespace tessera::server {

enum class LogLevel { kDebug, kInfo, kWarn, kError };

bool parse_log_level(std::string_view name, LogLevel* out);
void set_log_level(LogLevel level);
// Whether log(level, ...) writes a line: for callers whose fields cost something to gather.
bool log_enabled(LogLevel level);

// `fields` (an object, or null) are merged into the line; a "job" field names the job the line is about.
void log(LogLevel level, std::string_view msg, const nlohmann::json& fields = nullptr);

}  // namespace tessera::server
