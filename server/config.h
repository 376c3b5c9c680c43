// tesserad's configuration: every setting is a flag, an environment variable and a key of the JSON config file
// (--config FILE, keys as the long flags without the dashes). Precedence: flags > environment > config file >
// defaults.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "server/log.h"

namespace tessera::server {

struct Config {
  std::string listen = "127.0.0.1";
  int port = 8080;  // 0: any free port
  std::string data_dir = "./tessera-data";
  int threads = 0;   // render threads; 0: every hardware thread
  int max_jobs = 1;  // jobs rendering at once, sharing the render threads
  size_t max_body_bytes = 64u << 20;
  int max_width = 8192;
  int max_height = 8192;
  uint32_t max_spp = 65536;
  LogLevel log_level = LogLevel::kInfo;
  std::string config_file;              // where the values below may also come from
  std::string tokens_file;              // bearer tokens; empty: no authentication
  int max_user_priority = 100;          // above it, admin only (403)
  std::vector<std::string> cors_origins;
  int max_queued_per_user = 0;          // 0: no limit; above it 429
  double max_work = 0;                  // width x height x spp x max_depth; 0: no limit; above it 422
  double grace_s = 20;                  // SIGTERM: running jobs end their pass and checkpoint within this
  int http_threads = 256;               // cpp-httplib's pool: every SSE watcher and keep-alive connection holds one
  int keepalive_s = 15;                 // SSE heartbeat period
};

struct ConfigResult {
  std::optional<Config> config;  // nothing: print `error` (or the usage when `help`) and exit
  std::string error;
  bool help = false;
};

using GetEnv = std::function<const char*(const char*)>;
ConfigResult parse_config(int argc, const char* const* argv, const GetEnv& getenv);
std::string config_usage();

}  // namespace tessera::server
