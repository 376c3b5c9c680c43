// Supervised render workers: the daemon renders each run in a child process of its own (`tesserad --render-worker`,
// the daemon's own executable), so that a scene that crashes the renderer, or runs it out of memory, ends that
// process and never the daemon, as render managers run their renderers apart from themselves (Flamenco, OpenCue,
// Deadline). The worker loads and renders (render_work.h) confined (worker_sandbox.h): an address-space limit, no
// network, no programs, writes only beneath the data directory. The daemon keeps the API, the store and the leases.
// An uploaded asset is checked the same way, in a worker of its own (check_asset_in_worker).
//
// The protocol, lines of JSON over two pipes:
//   daemon -> worker (its standard input): {"worker": {...its environment...}, "request": RenderRequest}, then
//                    "stop" (end after the pass under way) or "cancel" (give it up); end of input: cancel, and exit
//   worker -> daemon (its descriptor 3):   {"loaded": ...}, {"resumed": ...}, {"pass": ...} after each pass, and
//                    {"ended": RunEnd} last (RunListener's calls, in their order)
// A worker that exits without "ended" crashed: its run ends RunOutcome::kCrashed, with an error that names how (the
// signal, the exit status, the memory limit). One that does not go within a grace period after a cancel is killed
// (SIGKILL, which it cannot ignore).
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <stop_token>
#include <string>

#include <nlohmann/json_fwd.hpp>

#include "server/jobs/render_work.h"

namespace tessera::server {

struct WorkerOptions {
  // The program run as `<executable> --render-worker`: the daemon's own (the file it was started from, even if it
  // was replaced on disk since).
  std::filesystem::path executable = "/proc/self/exe";
  std::filesystem::path data_dir;  // the only place a worker writes
  int threads = 1;                 // render threads of each worker
  uint64_t max_gltf_instances = 1'000'000;
  uint64_t memory_limit = 0;  // a worker's address space (RLIMIT_AS), in bytes; 0: not limited
  uint64_t open_files = 1024;
  uint64_t cpu_seconds = 0;  // a worker's CPU time (RLIMIT_CPU); 0: not limited (an asset check's is)
  // After a cancel, how long a worker has to exit before it is killed.
  std::chrono::milliseconds kill_grace{5000};
};

class WorkerProcessRunner final : public RenderRunner {
 public:
  explicit WorkerProcessRunner(WorkerOptions options) : options_(std::move(options)) {}
  void run(const RenderRequest& request, RunControl& control, RunListener& listener) override;
  int threads() const override { return options_.threads; }
  const char* where() const override { return "in a worker process"; }

 private:
  WorkerOptions options_;
};

// How a worker that died without reporting its end went, for its job's error: "the renderer crashed on this scene
// (SIGSEGV)", "the render worker was killed (SIGKILL) ...", "the render worker exited with status 3". `wait_status`
// as waitpid() gives it.
std::string describe_worker_exit(int wait_status);

// `tesserad --render-worker`: the worker's side of the protocol above. Returns the process's exit status.
int render_worker_main();

// An uploaded asset checked in a worker process (`tesserad --check-worker`), under the same confinement and a limit
// of CPU time too: `scene` (whose asset references all name `main_file`) loaded as the renderer will, without building
// it (SceneLoadOptions::build false). Throws SceneError naming what is wrong, a crash of the loader or a limit
// included, and LoadStopped once `stop` is asked (the worker is then killed).
void check_asset_in_worker(const WorkerOptions& worker, const nlohmann::json& scene,
                           const std::filesystem::path& main_file, std::stop_token stop);
// `tesserad --check-worker`: reads {"worker", "scene", "file"}, writes {"checked": {"error", "pointer"}}.
int asset_check_worker_main();

}  // namespace tessera::server
