// tesserad's configuration: every setting is a flag, an environment variable and a key of the JSON config file
// (--config FILE, keys as the long flags without the dashes). Precedence: flags > environment > config file >
// defaults.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "server/base/log.h"
#include "server/store/work_units.h"

namespace tessera::server {

struct Config {
  std::string listen = "127.0.0.1";
  int port = 8080;  // 0: any free port
  std::string data_dir = "./tessera-data";
  // Where the jobs are kept: "sqlite" (jobs.db in the data directory, this daemon's alone) or a PostgreSQL URI
  // (postgresql://user:password@host:port/database?..., libpq's syntax) that several daemons may share.
  std::string store = "sqlite";
  std::string node;     // this daemon's name in a shared store (the jobs it claims); empty: the host name
  double lease_s = 30;  // a claim not renewed for this long may be taken over by another daemon
  // On a shared store, jobs are split into work units of about this many pixel samples (work_units.h); 0: never.
  uint64_t unit_pixel_samples = kDefaultUnitPixelSamples;
  int threads = 0;   // render threads; 0: every hardware thread
  int max_jobs = 1;  // jobs rendering at once, each in a worker process with `threads` render threads
  size_t max_body_bytes = 64u << 20;
  int max_width = 8192;
  int max_height = 8192;
  uint32_t max_spp = 65536;
  uint64_t max_frames = 10000;  // frames of one render.frames range
  LogLevel log_level = LogLevel::kInfo;
  std::string config_file;      // where the values below may also come from
  std::string tokens_file;      // bearer tokens; empty: no authentication
  int max_user_priority = 100;  // above it, admin only (403)
  std::vector<std::string> cors_origins;
  int max_queued_per_user = 0;   // 0: no limit; above it 429
  int max_running_per_user = 0;  // runs one owner holds at once across the store's nodes; 0: no limit
  int crash_retries = 2;         // lost runs of a job (its renderer died while rendering it) before it fails
  // A render worker's address space (RLIMIT_AS), in bytes; nothing: the machine's physical memory; 0: no limit.
  std::optional<uint64_t> worker_memory;
  uint64_t asset_check_cpu_s = 120;         // CPU seconds an upload's check may take in its worker; past it: 422
  double max_work = 0;                      // width x height x spp x max_depth; 0: no limit; above it 422
  size_t max_film_bytes = size_t{8} << 30;  // a job's film with its passes; 0: no limit; above it 422
  uint64_t max_gltf_instances = 1'000'000;  // node instances of a glTF (paths through its hierarchy); above: 422
  double grace_s = 20;                      // SIGTERM: running jobs end their pass and checkpoint within this
  int http_threads = 64;                    // workers for ordinary requests (not event streams, not idle connections)
  int body_threads = 16;                    // workers for requests whose body is still arriving (queued beyond)
  int max_event_streams = 256;              // event streams sent at once (each holds a thread of its own); more: 503
  int max_connections = 1024;               // open connections; more: 503
  int max_connections_per_client = 32;      // open connections of one remote address; more: 429; 0: no cap
  double header_timeout_s = 10;             // a request's line and headers must arrive within this; else 408
  uint64_t min_transfer_rate = 16u << 10;   // bytes/s a body or response must average after 10 s; 0: no minimum
  int keepalive_s = 15;                     // SSE heartbeat period
  uint64_t min_free_disk_bytes = 256ull << 20;  // below it on the data dir's filesystem, new jobs/assets are 507
  int64_t retain_finished_s = 0;                // finished jobs older than this are deleted; 0: kept forever
};

// Whether `store` names a PostgreSQL database (a postgresql:// or postgres:// URI) rather than "sqlite".
bool is_postgres_store(std::string_view store);

struct ConfigResult {
  std::optional<Config> config;  // nothing: print `error` (or the usage when `help`) and exit
  std::string error;
  bool help = false;
  bool version = false;  // --version: print it and exit
};

// "268435456", "512MiB", "2GiB", "1G" (K, M, G, T, P: powers of 1000, with "B" too; KiB ... PiB: of 1024). Nothing
// when the text is not such a size or does not fit 64 bits, with the reason in `error`.
std::optional<uint64_t> parse_byte_size(std::string_view text, std::string* error = nullptr);
// "30d", "12h", "15m", "90s" or plain seconds ("3600"), at most 100 years. Nothing when malformed, with the reason.
std::optional<int64_t> parse_duration_s(std::string_view text, std::string* error = nullptr);

using GetEnv = std::function<const char*(const char*)>;
ConfigResult parse_config(int argc, const char* const* argv, const GetEnv& getenv);
std::string config_usage();

}  // namespace tessera::server
