#include "server/config.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>

#include "proto/did_you_mean.h"

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

std::function<std::string(Config&, const std::string&)> real(double Config::*field, double lo, double hi) {
  return [=](Config& c, const std::string& v) -> std::string {
    double x = 0;
    auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), x);
    if (ec != std::errc() || end != v.data() + v.size() || !std::isfinite(x) || x < lo || x > hi)
      return "must be a number from " + std::to_string(lo) + " to " + std::to_string(hi);
    c.*field = x;
    return "";
  };
}

std::function<std::string(Config&, const std::string&)> text(std::string Config::*field) {
  return [=](Config& c, const std::string& v) -> std::string {
    if (v.empty()) return "must not be empty";
    c.*field = v;
    return "";
  };
}

// The leading decimal digits of `text` as a number and the rest as its unit; false when there are no digits or they
// do not fit 64 bits (`*too_large` then).
bool split_number(std::string_view text, uint64_t* n, std::string_view* unit, bool* too_large) {
  auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), *n);
  *too_large = ec == std::errc::result_out_of_range;
  if (ec != std::errc()) return false;
  *unit = text.substr(static_cast<size_t>(end - text.data()));
  return true;
}

bool same_letters(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) == std::tolower(static_cast<unsigned char>(y));
         });
}

constexpr int64_t kMaxDurationS = 36500ll * 86400;  // 100 years: far beyond any retention, far below int64 ms

}  // namespace

std::optional<uint64_t> parse_byte_size(std::string_view text, std::string* error) {
  const std::string wanted = "must be a size in bytes like 268435456, 512MiB, 2GiB or 1G";
  auto fail = [&](const std::string& why) -> std::optional<uint64_t> {
    if (error) *error = why;
    return std::nullopt;
  };
  uint64_t n = 0;
  std::string_view unit;
  bool too_large = false;
  if (!split_number(text, &n, &unit, &too_large))
    return fail(too_large ? "is too large (more than 2^64-1 bytes)"
                          : wanted + ", not \"" + std::string(text.substr(0, 64)) + "\"");
  static constexpr struct {
    const char* unit;
    uint64_t bytes;
  } kUnits[] = {{"", 1},
                {"B", 1},
                {"K", 1000},
                {"KB", 1000},
                {"KiB", 1ull << 10},
                {"M", 1000000},
                {"MB", 1000000},
                {"MiB", 1ull << 20},
                {"G", 1000000000},
                {"GB", 1000000000},
                {"GiB", 1ull << 30},
                {"T", 1000000000000},
                {"TB", 1000000000000},
                {"TiB", 1ull << 40},
                {"P", 1000000000000000},
                {"PB", 1000000000000000},
                {"PiB", 1ull << 50}};
  for (const auto& u : kUnits) {
    if (!same_letters(unit, u.unit)) continue;
    if (n > std::numeric_limits<uint64_t>::max() / u.bytes) return fail("is too large (more than 2^64-1 bytes)");
    return n * u.bytes;
  }
  return fail(wanted + "; \"" + std::string(unit.substr(0, 16)) + "\" is not a unit (B, K, M, G, T, P, KiB ... PiB)");
}

std::optional<int64_t> parse_duration_s(std::string_view text, std::string* error) {
  const std::string wanted = "must be a duration like 30d, 12h, 15m, 90s or a number of seconds";
  auto fail = [&](const std::string& why) -> std::optional<int64_t> {
    if (error) *error = why;
    return std::nullopt;
  };
  uint64_t n = 0;
  std::string_view unit;
  bool too_large = false;
  const std::string too_long = "is too long (at most 36500d)";
  if (!split_number(text, &n, &unit, &too_large))
    return fail(too_large ? too_long : wanted + ", not \"" + std::string(text.substr(0, 64)) + "\"");
  uint64_t seconds_per = 0;
  if (unit.empty() || unit == "s") seconds_per = 1;
  if (unit == "m") seconds_per = 60;
  if (unit == "h") seconds_per = 3600;
  if (unit == "d") seconds_per = 86400;
  if (seconds_per == 0)
    return fail(wanted + "; \"" + std::string(unit.substr(0, 16)) + "\" is not a unit (s, m, h, d)");
  if (n > static_cast<uint64_t>(kMaxDurationS) / seconds_per) return fail(too_long);
  return static_cast<int64_t>(n * seconds_per);
}

namespace {

// A setting read into `field` by `parse`, whose error says what is wrong with the value.
template <typename T>
std::function<std::string(Config&, const std::string&)> parsed(T Config::*field,
                                                               std::optional<T> (*parse)(std::string_view,
                                                                                         std::string*)) {
  return [=](Config& c, const std::string& v) -> std::string {
    std::string error;
    const std::optional<T> value = parse(v, &error);
    if (!value) return error;
    c.*field = *value;
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
      {"--store", "TESSERA_STORE", "STORE",
       "where jobs are kept: sqlite (in the data dir; the default) or postgresql://user:pass@host/db, shared",
       [](Config& c, const std::string& v) -> std::string {
         if (v != "sqlite" && !is_postgres_store(v))
           return "must be sqlite or a PostgreSQL URI (postgresql://user:password@host:port/database)";
         c.store = v;
         return "";
       }},
      {"--node", "TESSERA_NODE", "NAME", "this daemon's name in a shared store (default: the host name)",
       [](Config& c, const std::string& v) -> std::string {
         // It names a lock file in a data directory daemons may share.
         if (v.empty() || v.size() > 64 || v.front() == '.' || !std::all_of(v.begin(), v.end(), [](char ch) {
               return std::isalnum(static_cast<unsigned char>(ch)) || ch == '-' || ch == '_' || ch == '.';
             }))
           return "must be 1 to 64 letters, digits, '-', '_' or '.', not starting with '.'";
         c.node = v;
         return "";
       }},
      {"--lease-s", "TESSERA_LEASE_S", "S",
       "seconds a job's claim lasts unless renewed (every quarter of it, at least once a second); past it another "
       "daemon takes the job over (30)",
       real(&Config::lease_s, 1, 3600)},
      {"--unit-pixel-samples", "TESSERA_UNIT_PIXEL_SAMPLES", "N",
       "on a PostgreSQL store, split a job's samples into units of about N pixel samples (width x height x samples) "
       "that the nodes render at once; 0: never split (20000000, tens of seconds of one thread)",
       integer(&Config::unit_pixel_samples, 0, 1ll << 50)},
      {"--threads", "TESSERA_THREADS", "N", "render threads (default 0: every hardware thread)",
       integer(&Config::threads, 0, 4096)},
      {"--max-jobs", "TESSERA_MAX_JOBS", "N",
       "jobs rendering at once, each in a worker process of --threads threads (default 1)",
       integer(&Config::max_jobs, 1, 1024)},
      {"--max-body-bytes", "TESSERA_MAX_BODY_BYTES", "N", "largest request body (default 67108864)",
       integer(&Config::max_body_bytes, 1024, 1ll << 40)},
      {"--max-width", "TESSERA_MAX_WIDTH", "N", "largest image width (default 8192)",
       integer(&Config::max_width, 1, 65536)},
      {"--max-height", "TESSERA_MAX_HEIGHT", "N", "largest image height (default 8192)",
       integer(&Config::max_height, 1, 65536)},
      {"--max-spp", "TESSERA_MAX_SPP", "N", "largest samples-per-pixel budget (default 65536)",
       integer(&Config::max_spp, 1, 1 << 24)},
      {"--max-frames", "TESSERA_MAX_FRAMES", "N", "most frames of one job's frame range (default 10000)",
       integer(&Config::max_frames, 1, 100'000'000)},
      {"--log-level", "TESSERA_LOG_LEVEL", "LEVEL", "debug, info, warn or error (default info)",
       [](Config& c, const std::string& v) -> std::string {
         return parse_log_level(v, &c.log_level) ? "" : "must be debug, info, warn or error";
       }},
      {"--config", "TESSERA_CONFIG", "FILE", "JSON file with the same keys as these flags (without --)",
       text(&Config::config_file)},
      {"--tokens", "TESSERA_TOKENS", "FILE",
       "bearer tokens: JSON array of {token, name, role: user|admin}; re-read on SIGHUP (default: no auth)",
       text(&Config::tokens_file)},
      {"--max-user-priority", "TESSERA_MAX_USER_PRIORITY", "N", "highest priority a user may set; above: admin (100)",
       integer(&Config::max_user_priority, -100, 100)},
      {"--cors-origin", "TESSERA_CORS_ORIGIN", "ORIGINS",
       "origins allowed cross-origin, comma-separated, repeatable (default none)",
       [](Config& c, const std::string& v) -> std::string {
         std::stringstream ss(v);
         std::string o;
         while (std::getline(ss, o, ',')) {
           if (o.empty()) continue;
           if (o != "*" && o.rfind("http://", 0) != 0 && o.rfind("https://", 0) != 0)
             return "must be origins like https://host:port, not \"" + o + "\"";
           c.cors_origins.push_back(o);
         }
         return "";
       }},
      {"--max-queued-per-user", "TESSERA_MAX_QUEUED_PER_USER", "N",
       "queued jobs one owner may have; more is 429 (default 0: no limit)",
       integer(&Config::max_queued_per_user, 0, 1 << 30)},
      {"--max-running-per-user", "TESSERA_MAX_RUNNING_PER_USER", "N",
       "jobs (or work units of split jobs) one owner renders at once across every node sharing the store; the rest "
       "wait while other owners' jobs run (default 0: no limit)",
       integer(&Config::max_running_per_user, 0, 1 << 30)},
      {"--crash-retries", "TESSERA_CRASH_RETRIES", "N",
       "times a job is rendered again after its renderer died while rendering it (a crash, a kill, a node lost); "
       "past that it fails naming the crashes, never resumed at a start again (default 2)",
       integer(&Config::crash_retries, 0, 1000)},
      {"--worker-memory", "TESSERA_WORKER_MEMORY", "SIZE",
       "address space a render worker may reserve (RLIMIT_AS, which counts reservations, not only memory in use), "
       "e.g. 16GiB; a job whose render needs more fails naming the limit (default: the machine's physical memory; "
       "0: no limit)",
       [](Config& c, const std::string& v) -> std::string {
         std::string error;
         const std::optional<uint64_t> value = parse_byte_size(v, &error);
         if (!value) return error;
         c.worker_memory = *value;
         return "";
       }},
      {"--asset-check-cpu-s", "TESSERA_ASSET_CHECK_CPU_S", "S",
       "CPU seconds the check of an uploaded asset may take (in a worker process); past it the upload is 422 "
       "(default 120)",
       integer(&Config::asset_check_cpu_s, 1, 86400)},
      {"--max-work", "TESSERA_MAX_WORK", "N",
       "largest width*height*spp*max_depth of a job (max_depth + max_volume_depth where its media scatter), 422 above "
       "(0: no limit)",
       real(&Config::max_work, 0, 1e30)},
      {"--max-film-bytes", "TESSERA_MAX_FILM_BYTES", "N",
       "largest film a job may hold, its beauty and render passes (width x height x 56 bytes, and 16 a pass channel); "
       "422 above (default 8589934592; 0: no limit)",
       integer(&Config::max_film_bytes, 0, 1ll << 50)},
      {"--max-gltf-instances", "TESSERA_MAX_GLTF_INSTANCES", "N",
       "node instances of a glTF asset, counted per path through its hierarchy; more is 422 (default 1000000)",
       integer(&Config::max_gltf_instances, 1, 1ll << 50)},
      {"--grace-s", "TESSERA_GRACE_S", "S", "SIGTERM: seconds for running jobs to checkpoint and stop (default 20)",
       real(&Config::grace_s, 0, 3600)},
      {"--http-threads", "TESSERA_HTTP_THREADS", "N",
       "threads handling ordinary requests (default 64; event streams and idle connections hold none)",
       integer(&Config::http_threads, 2, 4096)},
      {"--body-threads", "TESSERA_BODY_THREADS", "N",
       "threads reading request bodies that had not all arrived with the headers (uploads); more wait for one, and "
       "the --http-threads stay free for status requests (default 16)",
       integer(&Config::body_threads, 1, 4096)},
      {"--max-event-streams", "TESSERA_MAX_EVENT_STREAMS", "N",
       "event streams sent at once, each on a thread of its own; more are 503 (default 256)",
       integer(&Config::max_event_streams, 1, 65536)},
      {"--max-connections", "TESSERA_MAX_CONNECTIONS", "N", "open connections; more are 503 and closed (default 1024)",
       integer(&Config::max_connections, 16, 1 << 20)},
      {"--max-connections-per-client", "TESSERA_MAX_CONNECTIONS_PER_CLIENT", "N",
       "open connections of one client address; more are 429 and closed (default 32; 0: no cap, e.g. behind a proxy)",
       integer(&Config::max_connections_per_client, 0, 1 << 20)},
      {"--header-timeout-s", "TESSERA_HEADER_TIMEOUT_S", "S",
       "a request's line and headers must arrive within this many seconds, else 408 (default 10)",
       real(&Config::header_timeout_s, 0.1, 3600)},
      {"--min-transfer-rate", "TESSERA_MIN_TRANSFER_RATE", "SIZE",
       "bytes per second a request body or a response must average after 10 s, e.g. 16KiB (default; 0: off)",
       parsed(&Config::min_transfer_rate, parse_byte_size)},
      {"--keepalive-s", "TESSERA_KEEPALIVE_S", "S", "seconds between SSE keep-alive comments (default 15)",
       integer(&Config::keepalive_s, 1, 3600)},
      {"--min-free-disk", "TESSERA_MIN_FREE_DISK", "SIZE",
       "refuse new jobs and uploads (507) while the data dir's disk has less free, e.g. 2GiB (default 256MiB; 0: off)",
       parsed(&Config::min_free_disk_bytes, parse_byte_size)},
      {"--retain-finished", "TESSERA_RETAIN_FINISHED", "DURATION",
       "delete succeeded/failed/cancelled jobs this long after they end, e.g. 30d, 12h (default 0: keep them)",
       parsed(&Config::retain_finished_s, parse_duration_s)},
  };
  return list;
}

}  // namespace

bool is_postgres_store(std::string_view store) {
  return store.starts_with("postgresql://") || store.starts_with("postgres://");
}

std::string config_usage() {
  std::string out =
      "usage: tesserad [options]\n\n"
      "The tessera render daemon: accepts render jobs over HTTP, renders them, serves the results.\n\n"
      "options (each also read from the environment variable shown, and from the --config file under the flag's\n"
      "name without the dashes; a flag wins over the environment, which wins over the file):\n";
  for (const Option& o : options()) {
    std::string left = std::string("  ") + o.flag + " " + o.value_name;
    left.resize(std::max<size_t>(left.size() + 1, 26), ' ');
    out += left + o.help + "  [" + o.env + "]\n";
  }
  out += "  -h, --help                this text\n";
  out += "  --version                 print the version\n";
  return out;
}

namespace {

const Option* find_option(const std::string& flag) {
  for (const Option& o : options())
    if (flag == o.flag) return &o;
  return nullptr;
}

// Applies the JSON config file: an object whose keys are the long flags without "--" ("data-dir", or "data_dir").
std::string apply_config_file(Config& config, const std::string& file) {
  std::ifstream in(file);
  if (!in) return "cannot read the config file " + file;
  std::ostringstream ss;
  ss << in.rdbuf();
  nlohmann::json doc = nlohmann::json::parse(ss.str(), nullptr, false);
  if (!doc.is_object()) return file + ": expected a JSON object of settings";
  for (const auto& [key, value] : doc.items()) {
    std::string flag = "--" + key;
    for (char& c : flag)
      if (c == '_') c = '-';
    const Option* o = find_option(flag);
    if (!o || flag == "--config") {
      std::vector<std::string> keys;
      for (const Option& known : options())
        if (std::string_view(known.flag) != "--config") keys.push_back(std::string(known.flag).substr(2));
      return file + ": unknown key \"" + key + "\"" + proto::did_you_mean(flag.substr(2), keys);
    }
    std::vector<std::string> values;
    if (value.is_array() && flag == "--cors-origin") {
      for (const auto& v : value) {
        if (!v.is_string()) return file + ": \"" + key + "\" must be an array of strings";
        values.push_back(v.get<std::string>());
      }
    } else if (value.is_string()) {
      values.push_back(value.get<std::string>());
    } else if (value.is_number_integer()) {
      values.push_back(std::to_string(value.get<long long>()));
    } else if (value.is_number()) {
      values.push_back(value.dump());
    } else {
      return file + ": \"" + key + "\" must be a string or a number";
    }
    for (const std::string& v : values)
      if (std::string e = o->apply(config, v); !e.empty()) return file + ": \"" + key + "\" " + e;
  }
  return "";
}

}  // namespace

ConfigResult parse_config(int argc, const char* const* argv, const GetEnv& getenv) {
  ConfigResult result;
  Config config;
  // The config file named by the flag (or else the environment) is read first: everything else overrides it.
  std::string config_file;
  if (const char* v = getenv("TESSERA_CONFIG"); v != nullptr) config_file = v;
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "--config" && i + 1 < argc) config_file = argv[i + 1];
    if (arg.rfind("--config=", 0) == 0) config_file = arg.substr(9);
  }
  if (!config_file.empty()) {
    if (std::string e = apply_config_file(config, config_file); !e.empty()) {
      result.error = e;
      return result;
    }
    config.config_file = config_file;
  }
  // Lists (--cors-origin) given at a higher level replace the lower level's, not add to them.
  bool cors_from_env = false;
  for (const Option& o : options()) {
    if (const char* v = getenv(o.env); v != nullptr) {
      if (std::string(o.flag) == "--cors-origin" && !cors_from_env) {
        config.cors_origins.clear();
        cors_from_env = true;
      }
      if (std::string e = o.apply(config, v); !e.empty()) {
        result.error = std::string(o.env) + " " + e;
        return result;
      }
    }
  }
  bool cors_from_flags = false;
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "-h" || arg == "--help") {
      result.help = true;
      return result;
    }
    if (arg == "--version") {
      result.version = true;
      return result;
    }
    std::string value;
    bool has_value = false;
    if (size_t eq = arg.find('='); arg.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = arg.substr(eq + 1);
      arg = arg.substr(0, eq);
      has_value = true;
    }
    const Option* option = find_option(arg);
    if (!option) {
      std::vector<std::string_view> flags = {"--help", "--version"};
      for (const Option& o : options()) flags.push_back(o.flag);
      result.error = "unknown option " + arg + proto::did_you_mean(arg, flags);
      return result;
    }
    if (!has_value) {
      if (i + 1 >= argc) {
        result.error = arg + " needs a value";
        return result;
      }
      value = argv[++i];
    }
    if (arg == "--cors-origin" && !cors_from_flags) {
      config.cors_origins.clear();
      cors_from_flags = true;
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
