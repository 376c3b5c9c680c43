#include "server/config.h"

#include <charconv>
#include <vector>

namespace tessera::server {

namespace {

struct Option {
  const char* flag;
  const char* env;
  const char* value_name;
  const char* help;
  // Applies a value; returns an error message or "".
  std::function<std::string(Config&, const std::string&)> apply;
};

template <typename T>
std::function<std::string(Config&, const std::string&)> integer(T Config::*field, long long lo, long long hi) {
  return [=](Config& c, const std::string& v) -> std::string {
    long long n = 0;
    auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), n);
    if (ec != std::errc() || end != v.data() + v.size() || n < lo || n > hi)
      return "must be an integer from " + std::to_string(lo) + " to " + std::to_string(hi);
    c.*field = static_cast<T>(n);
    return "";
  };
}

const std::vector<Option>& options() {
  static const std::vector<Option> list = {
      {"--listen", "TESSERA_LISTEN", "ADDR", "address to listen on (default 127.0.0.1)",
       [](Config& c, const std::string& v) -> std::string {
         if (v.empty()) return "must not be empty";
         c.listen = v;
         return "";
       }},
      {"--port", "TESSERA_PORT", "N", "TCP port (default 8080; 0 picks a free port)", integer(&Config::port, 0, 65535)},
      {"--data-dir", "TESSERA_DATA_DIR", "DIR", "where jobs.db and job files live (default ./tessera-data)",
       [](Config& c, const std::string& v) -> std::string {
         if (v.empty()) return "must not be empty";
         c.data_dir = v;
         return "";
       }},
      {"--threads", "TESSERA_THREADS", "N", "render threads (default 0: every hardware thread)",
       integer(&Config::threads, 0, 4096)},
      {"--max-jobs", "TESSERA_MAX_JOBS", "N", "jobs rendering at once, sharing the threads (default 1)",
       integer(&Config::max_jobs, 1, 1024)},
      {"--max-body-bytes", "TESSERA_MAX_BODY_BYTES", "N", "largest request body (default 67108864)",
       integer(&Config::max_body_bytes, 1024, 1ll << 40)},
      {"--max-width", "TESSERA_MAX_WIDTH", "N", "largest image width (default 8192)",
       integer(&Config::max_width, 1, 65536)},
      {"--max-height", "TESSERA_MAX_HEIGHT", "N", "largest image height (default 8192)",
       integer(&Config::max_height, 1, 65536)},
      {"--max-spp", "TESSERA_MAX_SPP", "N", "largest samples-per-pixel budget (default 65536)",
       integer(&Config::max_spp, 1, 1 << 24)},
      {"--log-level", "TESSERA_LOG_LEVEL", "LEVEL", "debug, info, warn or error (default info)",
       [](Config& c, const std::string& v) -> std::string {
         return parse_log_level(v, &c.log_level) ? "" : "must be debug, info, warn or error";
       }},
  };
  return list;
}

}  // namespace

std::string config_usage() {
  std::string out =
      "usage: tesserad [options]\n\n"
      "The tessera render daemon: accepts render jobs over HTTP, renders them, serves the results.\n\n"
      "options (each also read from the environment variable shown; a flag wins):\n";
  for (const Option& o : options()) {
    std::string left = std::string("  ") + o.flag + " " + o.value_name;
    left.resize(std::max<size_t>(left.size() + 1, 26), ' ');
    out += left + o.help + "  [" + o.env + "]\n";
  }
  out += "  -h, --help                this text\n";
  return out;
}

ConfigResult parse_config(int argc, const char* const* argv, const GetEnv& getenv) {
  ConfigResult result;
  Config config;
  for (const Option& o : options()) {
    if (const char* v = getenv(o.env); v != nullptr) {
      if (std::string e = o.apply(config, v); !e.empty()) {
        result.error = std::string(o.env) + " " + e;
        return result;
      }
    }
  }
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "-h" || arg == "--help") {
      result.help = true;
      return result;
    }
    std::string value;
    bool has_value = false;
    if (size_t eq = arg.find('='); arg.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = arg.substr(eq + 1);
      arg = arg.substr(0, eq);
      has_value = true;
    }
    const Option* option = nullptr;
    for (const Option& o : options())
      if (arg == o.flag) option = &o;
    if (!option) {
      result.error = "unknown option " + arg;
      return result;
    }
    if (!has_value) {
      if (i + 1 >= argc) {
        result.error = arg + " needs a value";
        return result;
      }
      value = argv[++i];
    }
    if (std::string e = option->apply(config, value); !e.empty()) {
      result.error = arg + " " + e;
      return result;
    }
  }
  result.config = config;
  return result;
}

}  // namespace tessera::server
