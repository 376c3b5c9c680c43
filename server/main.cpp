// tesserad: the tessera render daemon. See `tesserad --help` and proto/openapi.json.
#include <httplib.h>
#include <pthread.h>
#include <signal.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <thread>

#include "renderer/thread_pool.h"
#include "server/config.h"
#include "server/http_api.h"
#include "server/job_files.h"
#include "server/log.h"
#include "server/scheduler.h"
#include "server/sqlite_job_store.h"

namespace {

using namespace tessera::server;

int run(const Config& config) {
  // SIGINT and SIGTERM are taken by one thread with sigwait(); every thread created from here on inherits the mask,
  // so no render or HTTP thread is interrupted by them.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  signal(SIGPIPE, SIG_IGN);  // a client that hangs up mid-download is not a reason to die

  const std::filesystem::path data_dir(config.data_dir);
  std::filesystem::create_directories(data_dir);
  SqliteJobStore store(data_dir / "jobs.db");
  JobFiles files(data_dir);
  tessera::ThreadPool pool(config.threads);

  SchedulerOptions scheduler_options;
  scheduler_options.max_jobs = config.max_jobs;
  scheduler_options.limits.max_width = config.max_width;
  scheduler_options.limits.max_height = config.max_height;
  scheduler_options.limits.max_spp = config.max_spp;
  Scheduler scheduler(store, files, pool, scheduler_options);

  ApiContext ctx{store, files, scheduler, {}, config.max_body_bytes};
  ctx.limits.render = scheduler_options.limits;
  httplib::Server http;
  install_api(http, ctx);

  int port = config.port;
  if (port == 0) {
    port = http.bind_to_any_port(config.listen);
    if (port < 0) port = 0;
  } else if (!http.bind_to_port(config.listen, port)) {
    port = 0;
  }
  if (port == 0) {
    log(LogLevel::kError, "cannot listen", {{"listen", config.listen}, {"port", config.port}});
    return 1;
  }
  scheduler.start();

  std::atomic<bool> listening_done{false};
  std::thread signal_thread([&] {
    int sig = 0;
    sigwait(&stop_signals, &sig);
    if (listening_done.load()) return;  // woken by main at exit
    log(LogLevel::kInfo, "stopping", {{"signal", sig == SIGINT ? "SIGINT" : "SIGTERM"}});
    // stop() is a no-op until the listen loop runs; repeat until it has taken effect.
    while (!listening_done.load()) {
      http.stop();
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
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
       {"max_jobs", config.max_jobs}});

  const bool clean = http.listen_after_bind();
  listening_done.store(true);
  pthread_kill(signal_thread.native_handle(), SIGTERM);  // releases sigwait if no signal came
  signal_thread.join();

  // Running renders are cancelled and their jobs go back to the queue for the next start.
  scheduler.shutdown();
  log(LogLevel::kInfo, "stopped");
  return clean ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  ConfigResult parsed = parse_config(argc, argv, [](const char* name) { return std::getenv(name); });
  if (parsed.help) {
    std::fputs(config_usage().c_str(), stdout);
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
