// tesserad's configuration: every setting is a flag and an environment variable (the flag wins).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>

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
