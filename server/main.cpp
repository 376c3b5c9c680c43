// tesserad: the tessera render daemon. See `tesserad --help` and proto/openapi.json.
#include <malloc.h>
#include <pthread.h>
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <thread>
#include <variant>

#include "renderer/thread_pool.h"
#include "server/base/auth.h"
#include "server/base/log.h"
#include "server/config.h"
#include "server/files/assets.h"
#include "server/files/data_dir_lock.h"
#include "server/files/events.h"
#include "server/files/job_files.h"
#include "server/http/http_api.h"
#include "server/http/http_transport.h"
#include "server/http/request_body.h"
#include "server/jobs/job_service.h"
#include "server/jobs/metrics.h"
#include "server/jobs/retention.h"
#include "server/jobs/scheduler.h"
#include "server/jobs/worker_process.h"
#include "server/store/postgres_event_bus.h"
#include "server/store/postgres_job_store.h"
#include "server/store/postgres_notifications.h"
#include "server/store/sqlite_job_store.h"

namespace {

using namespace tessera::server;

// A worker's address space: --worker-memory, or the machine's physical memory.
uint64_t worker_memory_limit(const Config& config) {
  return config.worker_memory.value_or(static_cast<uint64_t>(sysconf(_SC_PHYS_PAGES)) *
                                       static_cast<uint64_t>(sysconf(_SC_PAGESIZE)));
}

int run(const Config& config) {
  // Blocks of 1 MiB and more (request bodies, documents parsed from them) are mapped on their own and unmapped when
  // freed. glibc's default threshold rises with every large block freed, up to 32 MiB, after which such blocks come
  // from the per-thread heaps and stay resident when freed: each refused 50 MB body kept about 65 MB.
  mallopt(M_MMAP_THRESHOLD, 1 << 20);
  // SIGINT, SIGTERM and SIGHUP are taken by one thread with sigwait(); every thread created from here on inherits
  // the mask, so no render or HTTP thread is interrupted by them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  signal(SIGPIPE, SIG_IGN);  // a client that hangs up mid-download is not a reason to die

  std::unique_ptr<Auth> auth;
  try {
    auth = config.tokens_file.empty() ? std::make_unique<Auth>() : std::make_unique<Auth>(config.tokens_file);
  } catch (const std::exception& e) {
    log(LogLevel::kError, "cannot read the tokens", {{"error", e.what()}});
    return 2;
  }

  const std::filesystem::path data_dir(config.data_dir);
  std::filesystem::create_directories(data_dir);
  // The jobs in SQLite are this daemon's alone, and so is its data directory. In PostgreSQL they are shared by every
  // daemon given the same database, each claiming under its node name; their data directory may be shared too (a
  // volume every node mounts), each holding the lock of its own name.
  const bool shared_store = is_postgres_store(config.store);
  std::string node = config.node;
  if (node.empty()) {
    char host[256] = {};
    gethostname(host, sizeof host - 1);
    node = host;
  }
  auto lock = DataDirLock::acquire(data_dir, shared_store ? node : "");
  if (auto* error = std::get_if<std::string>(&lock)) {
    log(LogLevel::kError, "cannot start: " + *error, {{"data_dir", data_dir.string()}});
    std::fprintf(stderr, "tesserad: %s\n", error->c_str());
    return 1;
  }
  // What the daemon keeps, and where: its jobs, their files, the uploaded assets, and the events streamed to clients.
  std::unique_ptr<JobStore> store;
  if (shared_store) {
    try {
      // A node stopped mid-transaction holds its rows no longer than a lease: then they are the others' to take.
      store = std::make_unique<PostgresJobStore>(config.store, node, static_cast<int64_t>(config.lease_s * 1000));
    } catch (const JobStoreError& e) {
      log(LogLevel::kError, "cannot start: the job store cannot be opened", {{"error", e.what()}});
      std::fprintf(stderr, "tesserad: %s\n", e.what());
      return 1;
    }
    log(LogLevel::kInfo, "jobs are kept in PostgreSQL", {{"node", node}});
  } else {
    store = std::make_unique<SqliteJobStore>(data_dir / "jobs.db");
  }
  std::unique_ptr<JobFiles> files = std::make_unique<DirectoryJobFiles>(data_dir);
  // Asked to stop at SIGTERM/SIGINT: every scene load and asset check under way ends (a render's load, an upload's
  // check, a submitted job's check), so that none holds the daemon past --grace-s.
  std::stop_source stopping;
  AssetCheckOptions asset_check;
  asset_check.max_gltf_instances = config.max_gltf_instances;
  asset_check.stop = stopping.get_token();
  // Every render runs in a worker process of its own (worker_process.h): a scene that crashes the renderer ends that
  // process, never the daemon. Uploads are checked in one too, under a limit of CPU time: an asset that crashes the
  // loader is a 422.
  WorkerOptions worker;
  worker.data_dir = std::filesystem::absolute(data_dir);
  worker.max_gltf_instances = config.max_gltf_instances;
  worker.memory_limit = worker_memory_limit(config);
  WorkerOptions check_worker = worker;
  check_worker.cpu_seconds = config.asset_check_cpu_s;
  asset_check.load = [check_worker, stop = asset_check.stop](const nlohmann::json& scene,
                                                             const std::filesystem::path& file) {
    check_asset_in_worker(check_worker, scene, file, stop);
  };
  std::unique_ptr<AssetStore> assets = std::make_unique<DirectoryAssetStore>(data_dir, asset_check);
  // On a shared store, what changes on one node reaches the others as it happens: a dedicated connection LISTENs for
  // the jobs' changes (a render cancelled elsewhere stops at once) and the events clients stream, which are rows any
  // node reads. One daemon alone keeps its events in memory.
  std::unique_ptr<PostgresNotifications> notifications;
  std::unique_ptr<EventBus> events;
  if (shared_store) {
    notifications = std::make_unique<PostgresNotifications>(config.store, node);
    events = std::make_unique<PostgresEventBus>(config.store, node, *notifications);
  } else {
    events = std::make_unique<EventHub>();
  }
  tessera::ThreadPool pool(config.threads);
  // Loading (image decoding, mip levels, environment maps) borrows at most as many extra threads as render threads.
  tessera::limit_parallel_helpers(pool.size() - 1);
  Metrics metrics(node, shared_store ? "postgresql" : "sqlite");

  SchedulerOptions scheduler_options;
  scheduler_options.max_jobs = config.max_jobs;
  scheduler_options.max_running_per_user = config.max_running_per_user;
  scheduler_options.crash_retries = config.crash_retries;
  if (shared_store) scheduler_options.node = node;
  scheduler_options.lease = std::chrono::milliseconds(static_cast<int64_t>(config.lease_s * 1000));
  scheduler_options.resolve_asset = asset_resolver(*assets);
  scheduler_options.max_gltf_instances = config.max_gltf_instances;
  worker.threads = pool.size();
  scheduler_options.runner = std::make_shared<WorkerProcessRunner>(worker);
  Scheduler scheduler(*store, *files, pool, scheduler_options);
  JobServiceOptions service_options;
  service_options.max_user_priority = config.max_user_priority;
  service_options.max_queued_per_user = config.max_queued_per_user;
  service_options.unit_pixel_samples = config.unit_pixel_samples;
  service_options.node = scheduler_options.node;
  JobService jobs(*store, *files, *assets, scheduler, *events, metrics, service_options);
  // The notifications' handlers call the scheduler and the event bus: they stop first, however run() ends.
  struct StopListening {
    PostgresNotifications* n;
    ~StopListening() {
      if (n) n->stop();
    }
  } stop_listening{notifications.get()};

  SubmissionLimits limits;
  // A job's settings are judged against these once, at submission; its record keeps what was accepted.
  limits.render.max_width = config.max_width;
  limits.render.max_height = config.max_height;
  limits.render.max_spp = config.max_spp;
  limits.render.max_frames = config.max_frames;
  limits.max_work = config.max_work;
  limits.max_film_bytes = static_cast<uint64_t>(config.max_film_bytes);
  limits.resolve_asset = scheduler_options.resolve_asset;
  limits.max_gltf_instances = config.max_gltf_instances;
  limits.stop = stopping.get_token();
  ApiContext ctx{jobs,
                 *assets,
                 *events,
                 *auth,
                 metrics,
                 &pool,
                 limits,
                 config.max_body_bytes,
                 config.cors_origins,
                 config.keepalive_s,
                 config.min_free_disk_bytes,
                 data_dir};
  // Every connection holds a descriptor: the soft limit (often 1024) goes up to the hard one.
  if (rlimit open_files{}; getrlimit(RLIMIT_NOFILE, &open_files) == 0 && open_files.rlim_cur < open_files.rlim_max) {
    open_files.rlim_cur = open_files.rlim_max;
    setrlimit(RLIMIT_NOFILE, &open_files);
  }
  TransportLimits transport;
  transport.request_threads = config.http_threads;
  transport.body_threads = config.body_threads;
  transport.stream_threads = config.max_event_streams;
  transport.max_connections = config.max_connections;
  transport.max_connections_per_client = config.max_connections_per_client;
  transport.header_timeout_s = config.header_timeout_s;
  transport.min_rate_bytes_per_s = static_cast<double>(config.min_transfer_rate);
  // Bodies are limited where they are decoded (--max-body-bytes); on the wire, chunk framing and compression may
  // add to them, never this much.
  transport.max_body_wire_bytes = 2 * static_cast<uint64_t>(config.max_body_bytes) + (64u << 10);
  transport.is_long_lived = is_event_stream_target;
  transport.check_method = check_method;
  HttpTransport http(transport);
  ctx.transport = &http;
  if (notifications) ctx.store_notifications_up = [n = notifications.get()] { return n->connected(); };
  install_api(http, ctx);
  // SO_REUSEADDR only: a restart binds at once over connections in TIME_WAIT, but a second daemon on the port of a
  // running one fails to bind (cpp-httplib's default adds SO_REUSEPORT, with which the kernel would share the port
  // and split the requests between the two).
  http.set_socket_options([](socket_t sock) {
    int yes = 1;
    ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });

  const int port = http.bind(config.listen, config.port).value_or(0);
  if (port == 0) {
    const std::string error = std::strerror(errno);
    log(LogLevel::kError, "cannot listen", {{"listen", config.listen}, {"port", config.port}, {"error", error}});
    std::fprintf(stderr, "tesserad: cannot listen on %s port %d: %s%s\n", config.listen.c_str(), config.port,
                 error.c_str(),
                 errno == EADDRINUSE ? " (another process, perhaps another tesserad, has the port)" : "");
    return 1;
  }
  if (notifications) {
    notifications->listen(kJobsChannel, [&scheduler](const std::string& payload) {
      if (auto job = split_notification(payload)) scheduler.job_changed(job->first, job->second == "queued");
    });
    notifications->on_connected([&scheduler] { scheduler.recheck(); });
    notifications->start();
  }
  scheduler.start();
  // Finished jobs older than --retain-finished go as DELETE /v1/jobs/{id} would delete them.
  RetentionSweeper retention(*store, metrics, config.retain_finished_s,
                             [&jobs](const std::string& id, int64_t cutoff_ms) { return jobs.remove(id, cutoff_ms); });
  retention.start();

  std::atomic<bool> listening_done{false};
  std::thread signal_thread([&] {
    for (;;) {
      int sig = 0;
      sigwait(&signals, &sig);
      if (listening_done.load()) return;  // woken by main at exit
      if (sig == SIGHUP) {
        const std::string error = auth->reload();
        if (error.empty())
          log(LogLevel::kInfo, "tokens re-read", {{"enabled", auth->enabled()}});
        else
          log(LogLevel::kError, "cannot re-read the tokens; keeping the previous ones", {{"error", error}});
        continue;
      }
      log(LogLevel::kInfo, "stopping: no new jobs; running ones end their pass and checkpoint",
          {{"signal", sig == SIGINT ? "SIGINT" : "SIGTERM"}, {"grace_s", config.grace_s}});
      stopping.request_stop();
      scheduler.begin_drain();
      retention.stop();
      events->close();
      // stop() is a no-op until the listen loop runs; repeat until it has taken effect.
      while (!listening_done.load()) {
        http.stop();
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
      return;
    }
  });

  const bool ipv6 = config.listen.find(':') != std::string::npos;
  std::printf("listening on http://%s%s%s:%d\n", ipv6 ? "[" : "", config.listen.c_str(), ipv6 ? "]" : "", port);
  std::fflush(stdout);
  log(LogLevel::kInfo, "listening",
      {{"listen", config.listen},
       {"port", port},
       {"data_dir", std::filesystem::absolute(data_dir).string()},
       {"threads", pool.size()},
       {"max_jobs", config.max_jobs},
       {"http_threads", config.http_threads},
       {"body_threads", config.body_threads},
       {"tokens", auth->enabled()},
       {"min_free_disk_bytes", config.min_free_disk_bytes},
       {"retain_finished_s", config.retain_finished_s},
       {"config", config.config_file}});

  const auto started_stop = std::chrono::steady_clock::now();
  const bool clean = http.listen_after_bind();
  (void)started_stop;
  listening_done.store(true);
  pthread_kill(signal_thread.native_handle(), SIGTERM);  // releases sigwait if no signal came
  signal_thread.join();

  // Running renders end their pass (and checkpoint) within the grace time, else are cancelled; their jobs go back
  // to the queue and resume from the checkpoints on the next start.
  retention.stop();
  scheduler.shutdown(config.grace_s);
  if (notifications) notifications->stop();
  events->close();
  log(LogLevel::kInfo, "stopped");
  return clean ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  // The daemon runs itself as each render's worker process (worker_process.h).
  if (argc == 2 && std::strcmp(argv[1], "--render-worker") == 0) return tessera::server::render_worker_main();
  if (argc == 2 && std::strcmp(argv[1], "--check-worker") == 0) return tessera::server::asset_check_worker_main();
  ConfigResult parsed = parse_config(argc, argv, [](const char* name) { return std::getenv(name); });
  if (parsed.help) {
    std::fputs(config_usage().c_str(), stdout);
    return 0;
  }
  if (parsed.version) {
    std::printf("tesserad %s\n", TESSERA_VERSION);
    return 0;
  }
  if (!parsed.config) {
    std::fprintf(stderr, "tesserad: %s\n\n%s", parsed.error.c_str(), config_usage().c_str());
    return 2;
  }
  set_log_level(parsed.config->log_level);
  try {
    return run(*parsed.config);
  } catch (const std::exception& e) {
    log(LogLevel::kError, "fatal", {{"error", e.what()}});
    return 1;
  }
}
