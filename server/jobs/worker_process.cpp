#include "server/jobs/worker_process.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <iostream>
#include <mutex>
#include <optional>
#include <string_view>
#include <thread>

#include <nlohmann/json.hpp>

#include "renderer/scene_error.h"
#include "renderer/scene_loader.h"
#include "renderer/thread_pool.h"
#include "server/base/log.h"
#include "server/files/assets.h"
#include "server/jobs/worker_sandbox.h"

extern char** environ;

namespace tessera::server {

using nlohmann::json;

namespace {

constexpr int kReportFd = 3;  // the worker's descriptor for its reports
// A report longer than this is not one of the worker's (warnings are capped: scene.h kMaxWarnings).
constexpr size_t kMaxReportLine = 16u << 20;

// Writes all of `bytes`, retrying short writes; false when the other end is gone.
bool write_all(int fd, std::string_view bytes) {
  while (!bytes.empty()) {
    const ssize_t n = ::write(fd, bytes.data(), bytes.size());
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    bytes.remove_prefix(static_cast<size_t>(n));
  }
  return true;
}

std::string signal_name(int sig) {
  const char* abbrev = sigabbrev_np(sig);
  return abbrev ? std::string("SIG") + abbrev : "signal " + std::to_string(sig);
}

// The two pipes of a worker, closed when they go.
struct Fd {
  int fd = -1;
  Fd() = default;
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  ~Fd() { reset(); }
  void reset() {
    if (fd >= 0) ::close(fd);
    fd = -1;
  }
};

bool make_pipe(Fd& read_end, Fd& write_end) {
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0) return false;
  read_end.fd = fds[0];
  write_end.fd = fds[1];
  return true;
}

// The daemon's side of one worker: the reports it reads, dispatched to the listener; the end it heard.
class ReportReader {
 public:
  explicit ReportReader(RunListener& listener) : listener_(listener) {}

  // Takes a line of the worker's; false for one that is not a report (the worker is then not to be trusted).
  bool take(std::string_view line) {
    try {
      const json j = json::parse(line);
      if (auto it = j.find("pass"); it != j.end()) {
        last_progress_ = render_progress_from_json(it->at("progress"));
        listener_.pass(last_progress_, it->at("write_error").get<std::string>());
      } else if (auto it = j.find("frame"); it != j.end()) {
        listener_.frame(it->at("frame").get<int64_t>(), it->at("event").get<std::string>());
      } else if (auto it = j.find("loaded"); it != j.end()) {
        listener_.loaded(it->at("warnings").get<std::vector<std::string>>(), it->at("load_s").get<double>());
      } else if (auto it = j.find("resumed"); it != j.end()) {
        std::optional<RenderProgress> restored;
        if (!it->at("progress").is_null()) restored = last_progress_ = render_progress_from_json(it->at("progress"));
        listener_.resumed(restored, it->at("unusable").get<bool>());
      } else if (auto it = j.find("ended"); it != j.end()) {
        end_ = run_end_from_json(*it);
        if (!end_) return false;
      } else {
        return false;
      }
      return true;
    } catch (const json::exception&) {
      return false;
    }
  }
  const std::optional<RunEnd>& end() const { return end_; }
  const RenderProgress& last_progress() const { return last_progress_; }

 private:
  RunListener& listener_;
  RenderProgress last_progress_;
  std::optional<RunEnd> end_;
};

// A child process of the daemon that speaks lines of JSON: the daemon writes to its standard input and reads its
// descriptor 3. Killed and reaped, if still there, when it goes.
class WorkerChild {
 public:
  WorkerChild() = default;
  WorkerChild(const WorkerChild&) = delete;
  WorkerChild& operator=(const WorkerChild&) = delete;
  ~WorkerChild() {
    if (pid_ > 0) {
      kill();
      reap(std::chrono::milliseconds(0));
    }
  }

  // Starts `<executable> <mode>`: its standard input and descriptor 3 the pipes' ends, every other descriptor of the
  // daemon (its listening socket, its store) closed; its own process group, so that a terminal's Ctrl-C reaches the
  // daemon alone (which stops its renders in order); no signal blocked (the daemon blocks SIGTERM in every thread).
  bool start(const std::filesystem::path& executable, const char* mode, std::string* error) {
    Fd input_read, output_write;
    if (!make_pipe(input_read, input_) || !make_pipe(output_, output_write)) {
      *error = std::string("cannot make its pipes: ") + std::strerror(errno);
      return false;
    }
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, input_read.fd, 0);
    posix_spawn_file_actions_adddup2(&actions, output_write.fd, kReportFd);
    posix_spawn_file_actions_addclosefrom_np(&actions, kReportFd + 1);
    posix_spawnattr_t attr;
    posix_spawnattr_init(&attr);
    sigset_t none, defaults;
    sigemptyset(&none);
    sigemptyset(&defaults);
    for (int sig : {SIGPIPE, SIGINT, SIGTERM, SIGHUP}) sigaddset(&defaults, sig);
    posix_spawnattr_setsigmask(&attr, &none);
    posix_spawnattr_setsigdefault(&attr, &defaults);
    posix_spawnattr_setpgroup(&attr, 0);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF | POSIX_SPAWN_SETPGROUP);
    const std::string program = executable.string();
    std::string arg0 = "tesserad", arg1 = mode;
    char* argv[] = {arg0.data(), arg1.data(), nullptr};
    const int spawned = posix_spawn(&pid_, program.c_str(), &actions, &attr, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    posix_spawnattr_destroy(&attr);
    if (spawned != 0) {
      pid_ = -1;
      *error = program + ": " + std::strerror(spawned);
      return false;
    }
    return true;
  }

  pid_t pid() const { return pid_; }

  // Writes `line` and a newline to its input; false when it is gone (EPIPE: the daemon ignores SIGPIPE). After the
  // first line, a write never waits for a child that does not read.
  bool send(std::string_view line) {
    std::lock_guard lock(input_mutex_);
    if (input_.fd < 0) return false;
    const bool sent = write_all(input_.fd, std::string(line) + "\n");
    fcntl(input_.fd, F_SETFL, O_NONBLOCK);
    return sent;
  }
  // End of input: the child ends what it does and exits.
  void close_input() {
    std::lock_guard lock(input_mutex_);
    input_.reset();
  }

  // Hands each of its lines to `on_line` (false: not one of its reports, and the child is killed) until it closes its
  // end, calling `on_tick` about every 100 ms meanwhile.
  void read(const std::function<bool(std::string_view)>& on_line, const std::function<void()>& on_tick) {
    std::string buffer;
    char chunk[65536];
    for (;;) {
      pollfd p{output_.fd, POLLIN, 0};
      const int ready = ::poll(&p, 1, 100);
      if (ready < 0 && errno != EINTR) break;
      if (ready > 0) {
        const ssize_t n = ::read(output_.fd, chunk, sizeof chunk);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) break;  // the child closed its end: it exited
        buffer.append(chunk, static_cast<size_t>(n));
        size_t start = 0;
        for (size_t nl; (nl = buffer.find('\n', start)) != std::string::npos; start = nl + 1)
          if (!on_line(std::string_view(buffer).substr(start, nl - start))) {
            log(LogLevel::kError, "a worker wrote what is not a report; it is stopped", {{"pid", pid_}});
            kill();
          }
        buffer.erase(0, start);
        if (buffer.size() > kMaxReportLine) {
          log(LogLevel::kError, "a worker's report is too long; it is stopped", {{"pid", pid_}});
          kill();
          buffer.clear();
        }
      }
      on_tick();
    }
  }

  void kill() {
    if (pid_ > 0 && !killed_) ::kill(pid_, SIGKILL);
    killed_ = true;
  }
  bool killed() const { return killed_; }

  // Waits for the child's exit, killing it when it is not gone within `grace`; its wait status.
  int reap(std::chrono::milliseconds grace) {
    int status = 0;
    const auto deadline = std::chrono::steady_clock::now() + grace;
    for (;;) {
      const pid_t r = ::waitpid(pid_, &status, WNOHANG);
      if (r == pid_ || (r < 0 && errno != EINTR)) break;
      if (r == 0 && std::chrono::steady_clock::now() > deadline) kill();
      if (r == 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    pid_ = -1;
    return status;
  }

 private:
  pid_t pid_ = -1;
  Fd input_, output_;
  std::mutex input_mutex_;
  std::atomic<bool> killed_ = false;
};

// What a worker is told of its daemon and its limits: the first line's "worker" object (read_assignment,
// enter_sandbox).
json environment_of(const WorkerOptions& options) {
  return {{"data_dir", options.data_dir.string()},
          {"threads", options.threads},
          {"max_gltf_instances", options.max_gltf_instances},
          {"memory_limit", options.memory_limit},
          {"open_files", options.open_files},
          {"cpu_seconds", options.cpu_seconds},
          {"daemon_pid", static_cast<int64_t>(getpid())}};
}

RunEnd crashed(std::string error, const RenderProgress& progress) {
  RunEnd end;
  end.outcome = RunOutcome::kCrashed;
  end.error = std::move(error);
  end.progress = progress;
  return end;
}

}  // namespace

std::string describe_worker_exit(int status) {
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    const std::string name = signal_name(sig);
    if (sig == SIGKILL)
      return "the render worker was killed (" + name + "), by an operator or by the system when it ran out of memory";
    if (sig == SIGXCPU) return "the render worker ran out of CPU time (" + name + ")";
    return "the renderer crashed on this scene (" + name + ")";
  }
  if (WIFEXITED(status)) return "the render worker exited with status " + std::to_string(WEXITSTATUS(status));
  return "the render worker ended (wait status " + std::to_string(status) + ")";
}

void WorkerProcessRunner::run(const RenderRequest& request, RunControl& control, RunListener& listener) {
  WorkerChild worker;
  if (std::string error; !worker.start(options_.executable, "--render-worker", &error)) {
    listener.ended(crashed("cannot start a render worker: " + error, {}));
    return;
  }
  // A worker that dies at once leaves this unread: its exit says why.
  worker.send(json{{"worker", environment_of(options_)}, {"request", render_request_to_json(request)}}.dump());

  using Clock = std::chrono::steady_clock;
  std::mutex cancel_mutex;
  std::optional<Clock::time_point> cancelled_at;
  ReportReader reader(listener);
  {
    auto attached = control.attach([&](bool cancel) {
      worker.send(cancel ? "cancel" : "stop");
      std::lock_guard lock(cancel_mutex);
      if (cancel && !cancelled_at) cancelled_at = Clock::now();
    });
    worker.read([&](std::string_view line) { return reader.take(line); },
                [&] {
                  std::lock_guard lock(cancel_mutex);
                  if (cancelled_at && !worker.killed() && Clock::now() - *cancelled_at > options_.kill_grace) {
                    log(LogLevel::kWarn, "a render worker did not stop when cancelled; it is killed",
                        {{"job", request.id}, {"pid", worker.pid()}});
                    worker.kill();
                  }
                });
  }
  worker.close_input();  // a worker still running cancels its render and exits
  // Reaped before the run ends, so that a run's slot never outlives its worker: no more workers than --max-jobs.
  const int status = worker.reap(options_.kill_grace);
  if (reader.end()) {
    // It reported its end (its outputs are written): how it exited after does not change that.
    listener.ended(*reader.end());
    return;
  }
  if (worker.killed() && control.cancel_requested()) {
    // Killed because it did not stop when cancelled: an interrupted run, as the cancel asked.
    RunEnd end;
    end.outcome = RunOutcome::kInterrupted;
    end.reason = StopReason::kCancelled;
    end.progress = reader.last_progress();
    listener.ended(end);
    return;
  }
  listener.ended(crashed(describe_worker_exit(status), reader.last_progress()));
}

namespace {

// The worker's reports, one line each on descriptor 3.
class ReportWriter final : public RunListener {
 public:
  void loaded(const std::vector<std::string>& warnings, double load_s) override {
    send({{"loaded", {{"warnings", warnings}, {"load_s", load_s}}}});
  }
  void resumed(const std::optional<RenderProgress>& restored, bool unusable) override {
    send({{"resumed",
           {{"progress", restored ? render_progress_to_json(*restored) : json(nullptr)}, {"unusable", unusable}}}});
  }
  void pass(const RenderProgress& progress, const std::string& write_error) override {
    send({{"pass", {{"progress", render_progress_to_json(progress)}, {"write_error", write_error}}}});
  }
  void frame(int64_t frame, const std::string& event) override {
    send({{"frame", {{"frame", frame}, {"event", event}}}});
  }
  void ended(const RunEnd& end) override { send({{"ended", run_end_to_json(end)}}); }

 private:
  static void send(const json& report) {
    // A daemon that is gone reads no more: the worker then ends at the next stop it hears (its input closed).
    write_all(kReportFd, report.dump() + "\n");
  }
};

// The sandbox every worker enters before it reads anything of a client's (worker_sandbox.h), as its `environment`
// (environment_of) gives it: writes beneath the data directory, the limits. Failures are logged: a kernel without
// Landlock or seccomp still renders. Returns the limits.
SandboxLimits enter_sandbox(const json& environment, const std::string& job) {
  SandboxLimits limits;
  limits.address_space = environment.at("memory_limit").get<uint64_t>();
  limits.open_files = environment.at("open_files").get<uint64_t>();
  limits.cpu_seconds = environment.at("cpu_seconds").get<uint64_t>();
  const std::filesystem::path writable = environment.at("data_dir").get<std::string>();
  for (const std::string& failed : apply_limits(limits))
    log(LogLevel::kWarn, "a worker's limit could not be set", {{"job", job}, {"error", failed}});
  try {
    deny_network_and_exec();
  } catch (const std::exception& e) {
    log(LogLevel::kWarn, "a worker runs without its system-call filter", {{"job", job}, {"error", e.what()}});
  }
  if (std::string why; !confine_writes(writable, &why))
    log(LogLevel::kWarn, "a worker may write outside the data directory", {{"job", job}, {"why", why}});
  return limits;
}

// The first line of a worker's input, {"worker": {...}, ...}, from its daemon; nothing (the worker exits) when it does
// not read or its daemon is gone already.
std::optional<json> read_assignment() {
  // The worker dies with the daemon: at its death (PR_SET_PDEATHSIG), and at once if it is gone already (the worker
  // was adopted).
  prctl(PR_SET_PDEATHSIG, SIGKILL);
  std::string first;
  if (!std::getline(std::cin, first)) return std::nullopt;
  try {
    json j = json::parse(first);
    if (getppid() != j.at("worker").at("daemon_pid").get<pid_t>()) return std::nullopt;
    return j;
  } catch (const json::exception& e) {
    std::fprintf(stderr, "tesserad: a worker's assignment does not read: %s\n", e.what());
    return std::nullopt;
  }
}

}  // namespace

int render_worker_main() {
  const std::optional<json> assignment = read_assignment();
  if (!assignment) return 2;
  json environment;
  RenderRequest request;
  try {
    environment = assignment->at("worker");
    request = render_request_from_json(assignment->at("request"));
  } catch (const json::exception& e) {
    std::fprintf(stderr, "tesserad --render-worker: the request does not read: %s\n", e.what());
    return 2;
  }
  // Confined before anything of the scene is read.
  const uint64_t memory_limit = enter_sandbox(environment, request.id).address_space;
  const std::filesystem::path data_dir = environment.at("data_dir").get<std::string>();

  ReportWriter writer;
  try {
    const int threads = std::max(1, environment.at("threads").get<int>());
    ThreadPool pool(threads);
    limit_parallel_helpers(pool.size() - 1);
    DirectoryJobFiles files(data_dir);
    DirectoryAssetStore assets(data_dir, {}, false);
    RenderEnvironment env;
    env.files = &files;
    env.pool = &pool;
    env.resolve_asset = asset_resolver(assets);
    env.max_gltf_instances = environment.at("max_gltf_instances").get<uint64_t>();
    env.memory_limit = memory_limit;

    // The daemon's requests; the end of its input (it closed the pipe, or died) cancels the render. The control
    // lives as long as the process: the thread reading them is never joined.
    auto* control = new RunControl;
    std::thread([control] {
      std::string line;
      while (std::getline(std::cin, line)) {
        if (line == "stop") control->stop();
        if (line == "cancel") control->cancel();
      }
      control->cancel();
    }).detach();
    perform_render(request, env, *control, writer);
  } catch (const std::exception& e) {
    // The worker could not set itself up (its threads, under an address-space limit too low for their stacks): the
    // daemon's configuration is at fault, not the scene.
    RunEnd end;
    end.outcome = RunOutcome::kFailed;
    end.error =
        std::string("the render worker cannot start: ") + e.what() +
        (memory_limit ? " (is the " + describe_bytes(memory_limit) + " limit of --worker-memory too low?)" : "");
    writer.ended(end);
  }
  // The reports are written (unbuffered); nothing else is worth the time of destructors racing the reader thread.
  std::fflush(stderr);
  std::_Exit(0);
}

void check_asset_in_worker(const WorkerOptions& options, const json& scene, const std::filesystem::path& main_file,
                           std::stop_token stop) {
  WorkerChild worker;
  if (std::string error; !worker.start(options.executable, "--check-worker", &error))
    throw std::runtime_error("cannot start an asset check worker: " + error);
  worker.send(json{{"worker", environment_of(options)}, {"scene", scene}, {"file", main_file.string()}}.dump());
  std::optional<json> checked;
  bool stopped = false;
  // A check that does not end within twice its CPU time in wall time (a worker that blocks, or is stopped, uses no
  // CPU time) is killed too: an upload never waits on it without end.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(2 * options.cpu_seconds);
  bool overdue = false;
  worker.read(
      [&](std::string_view line) {
        const json j = json::parse(line, nullptr, false);
        if (!j.is_object() || !j.contains("checked")) return false;
        checked = j["checked"];
        return true;
      },
      [&] {
        if (stop.stop_requested() && !stopped) {
          stopped = true;
          worker.kill();
        }
        if (options.cpu_seconds && !overdue && std::chrono::steady_clock::now() > deadline) {
          overdue = true;
          worker.kill();
        }
      });
  worker.close_input();
  const int status = worker.reap(std::chrono::milliseconds(5000));
  if (stopped) throw LoadStopped();
  if (checked) {
    const std::string error = checked->value("error", "");
    if (error.empty()) return;
    throw SceneError(checked->value("pointer", ""), error);
  }
  if (overdue)
    throw SceneError("", "checking it took more than " + std::to_string(2 * options.cpu_seconds) +
                             " s (twice its CPU time limit, --asset-check-cpu-s)");
  if (WIFSIGNALED(status) && (WTERMSIG(status) == SIGXCPU || WTERMSIG(status) == SIGKILL))
    throw SceneError("", "checking it took more than " + std::to_string(options.cpu_seconds) +
                             " s of CPU time, or was killed (" + signal_name(WTERMSIG(status)) + ")");
  if (WIFSIGNALED(status))
    throw SceneError("", "checking it crashed the loader (" + signal_name(WTERMSIG(status)) + ")");
  throw SceneError("", "checking it ended the check worker (" + describe_worker_exit(status) + ")");
}

int asset_check_worker_main() {
  const std::optional<json> assignment = read_assignment();
  if (!assignment) return 2;
  json result;
  try {
    const json& environment = assignment->at("worker");
    const SandboxLimits limits = enter_sandbox(environment, "");
    const std::filesystem::path file = assignment->at("file").get<std::string>();
    SceneLoadOptions options;
    options.build = false;
    options.max_gltf_instances = environment.at("max_gltf_instances").get<uint64_t>();
    options.resolve_asset = [&](const std::string&, const std::string&) { return file; };
    try {
      load_scene(assignment->at("scene"), "", options);
      result = {{"error", ""}};
    } catch (const SceneError& e) {
      result = {{"error", e.what()}, {"pointer", e.pointer()}};
    } catch (const std::bad_alloc&) {
      result = {{"error", "checking it needs more than the " + describe_bytes(limits.address_space) +
                              " memory limit of a worker (--worker-memory)"}};
    }
  } catch (const std::exception& e) {
    result = {{"error", std::string("cannot be checked: ") + e.what()}};
  }
  write_all(kReportFd, json{{"checked", result}}.dump() + "\n");
  std::fflush(stderr);
  std::_Exit(0);
}

}  // namespace tessera::server
