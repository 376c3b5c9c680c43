// Supervised render workers: the real daemon renders each job in a child process (worker_process.h). A worker that
// dies, whatever kills it, fails or retries its run and the daemon stays up; a retried render ends with the bits of
// an uninterrupted one; a render that needs more memory than a worker may take fails with an error that says so.
#include <signal.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <functional>
#include <thread>

#include "tests/integration/daemon.h"
#include "tests/integration/daemon_client.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const std::vector<std::string> kArgs = {"--threads", "2", "--max-jobs", "1", "--log-level", "debug"};

bool eventually(const std::function<bool()>& done, double timeout_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < deadline) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

// A process's command line, its arguments joined by spaces.
std::string command_line(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/cmdline", std::ios::binary);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::replace(text.begin(), text.end(), '\0', ' ');
  return text;
}

// The worker rendering a job of `daemon`'s, once it has rendered a pass (its checkpoint exists).
pid_t worker_after_a_pass(Daemon& daemon, httplib::Client& c, const std::string& id, int64_t samples_above = 0) {
  pid_t worker = 0;
  const bool found = eventually(
      [&] {
        const json s = get_job(c, id);
        if (s.value("state", "") != "running" || s["progress"].value("samples_done", 0) <= samples_above) return false;
        const std::vector<pid_t> children = children_of(daemon.pid());
        if (children.size() != 1) return false;
        worker = children.front();
        return true;
      },
      60);
  EXPECT_TRUE(found) << "no worker rendering job " << id << ": " << get_job(c, id).dump();
  return found ? worker : 0;
}

// A scene that crashes the renderer (here: its worker aborts, as Embree's assertions and Draco's do) fails its job
// after --crash-retries retries, with an error that names the crash, while the daemon answers throughout; a restart
// does not render it again.
TEST(Workers, ADaemonOutlivesItsRenderersCrashesAndTheJobFailsNamingThem) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  std::string id;
  json finished_at;
  {
    Daemon daemon(data, kArgs);
    auto c = daemon.client();
    id = submit(*c, long_cornell_job());
    for (int run = 0; run < 3; ++run) {  // the first run and --crash-retries (2) retries
      const pid_t worker = worker_after_a_pass(daemon, *c, id);
      ASSERT_GT(worker, 0) << daemon.log();
      ASSERT_EQ(kill(worker, SIGABRT), 0);
      // Waits for this worker's end to be recorded: a retry renders in another process.
      ASSERT_TRUE(eventually(
          [&] {
            const auto children = children_of(daemon.pid());
            return std::find(children.begin(), children.end(), worker) == children.end() &&
                   (state_of(*c, id) == "failed" || (run < 2 && children.size() == 1));
          },
          60))
          << daemon.log();
      auto live = c->Get("/livez");
      ASSERT_TRUE(live && live->status == 200) << "the daemon did not answer after its worker crashed";
    }
    ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "failed"; }, 30)) << daemon.log();
    const json failed = get_job(*c, id);
    EXPECT_NE(failed.value("error", "").find("the renderer crashed on this scene (SIGABRT)"), std::string::npos)
        << failed.dump();
    EXPECT_NE(failed.value("error", "").find("3 runs of this job were lost"), std::string::npos) << failed.dump();
    const std::string log = fetch(*c, "/v1/jobs/" + id + "/log");
    EXPECT_NE(log.find("(retry 1 of 2)"), std::string::npos) << log;
    EXPECT_NE(log.find("(retry 2 of 2)"), std::string::npos) << log;
    finished_at = failed.at("finished_at");
    EXPECT_EQ(daemon.stop(SIGTERM), 0);
  }
  Daemon daemon(data, kArgs);
  auto c = daemon.client();
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const json again = get_job(*c, id);
  EXPECT_EQ(again.value("state", ""), "failed") << again.dump();
  EXPECT_EQ(again.at("finished_at"), finished_at) << "rendered again after a restart: " << again.dump();
  EXPECT_TRUE(children_of(daemon.pid()).empty()) << "a worker renders the failed job";
  EXPECT_EQ(daemon.stop(SIGTERM), 0);
}

// A worker killed mid-render (SIGKILL: the system out of memory, an operator) is retried from the job's checkpoint,
// and the image has the bits of a render never interrupted: sampling is deterministic in (seed, pixel, sample).
TEST(Workers, AWorkerKilledMidRenderIsRetriedAndTheImageIsBitIdentical) {
  TempDir dir;
  Daemon daemon(dir.path() / "data", kArgs);
  auto c = daemon.client();
  const json doc = cornell_job(96, 512);
  const std::string reference = submit(*c, doc);
  ASSERT_TRUE(eventually([&] { return state_of(*c, reference) == "succeeded"; }, 240)) << daemon.log();
  const std::string id = submit(*c, doc);
  const pid_t worker = worker_after_a_pass(daemon, *c, id, 8);
  ASSERT_GT(worker, 0) << daemon.log();
  ASSERT_EQ(kill(worker, SIGKILL), 0);
  ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "succeeded"; }, 240)) << daemon.log();
  const std::string log = fetch(*c, "/v1/jobs/" + id + "/log");
  EXPECT_NE(log.find("the render worker was killed (SIGKILL)"), std::string::npos) << log;
  EXPECT_NE(log.find("resuming from its checkpoint"), std::string::npos) << log;
  EXPECT_TRUE(fetch(*c, "/v1/jobs/" + id + "/result.exr") == fetch(*c, "/v1/jobs/" + reference + "/result.exr"))
      << "the retried render's EXR differs from the uninterrupted one";
  EXPECT_TRUE(fetch(*c, "/v1/jobs/" + id + "/result.png") == fetch(*c, "/v1/jobs/" + reference + "/result.png"));
}

// A render that needs more memory than --worker-memory lets a worker reserve fails at once, naming the limit; it is
// not retried, and the daemon renders the next job.
TEST(Workers, ARenderAboveTheWorkerMemoryLimitFailsNamingIt) {
  TempDir dir;
  std::vector<std::string> args = kArgs;
  args.insert(args.end(),
              {"--worker-memory", "2GiB", "--max-width", "8192", "--max-height", "8192", "--max-film-bytes", "0"});
  Daemon daemon(dir.path() / "data", args);
  auto c = daemon.client();
  // 8192 x 8192 pixels: a film of 3.5 GiB.
  json big = cornell_job(8192, 1);
  const std::string id = submit(*c, big);
  ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "failed"; }, 60)) << daemon.log();
  const json failed = get_job(*c, id);
  EXPECT_NE(failed.value("error", "").find("needs more than the 2 GiB memory limit of a render worker"),
            std::string::npos)
      << failed.dump();
  EXPECT_EQ(fetch(*c, "/v1/jobs/" + id + "/log").find("retry"), std::string::npos) << "a refused render was retried";
  const std::string next = submit(*c, cornell_job(32, 4));
  EXPECT_TRUE(eventually([&] { return state_of(*c, next) == "succeeded"; }, 60)) << daemon.log();
}

// An upload is checked in a worker process of its own: a check that crashes (here: killed with SIGSEGV while it
// starts) makes the upload a 422 naming the file and the crash, and the daemon goes on taking uploads.
// The Duck uploaded to `daemon`, its check worker sent `signal` once it is seen.
struct SignalledUpload {
  bool checker_seen = false;
  int status = 0;
  std::string body;
};
SignalledUpload upload_signalling_the_check(Daemon& daemon, const httplib::MultipartFormDataItems& items, int signal) {
  SignalledUpload result;
  std::thread upload([&] {
    if (auto res = daemon.client()->Post("/v1/assets", items)) {
      result.status = res->status;
      result.body = res->body;
    }
  });
  pid_t checker = 0;
  result.checker_seen = eventually(
      [&] {
        for (pid_t child : children_of(daemon.pid()))
          if (command_line(child).find("--check-worker") != std::string::npos) checker = child;
        return checker > 0;
      },
      30);
  if (result.checker_seen) kill(checker, signal);
  upload.join();
  return result;
}

httplib::MultipartFormDataItems duck_upload() {
  return {
      {"file", read_text(fs::path(TESSERA_SOURCE_DIR) / "examples/duck/Duck.glb"), "Duck.glb", "model/gltf-binary"}};
}

TEST(Workers, AnUploadWhoseCheckCrashesIsRefusedAndTheDaemonGoesOn) {
  TempDir dir;
  Daemon daemon(dir.path() / "data", kArgs);
  auto c = daemon.client();
  const httplib::MultipartFormDataItems items = duck_upload();
  const SignalledUpload crashed = upload_signalling_the_check(daemon, items, SIGSEGV);
  ASSERT_TRUE(crashed.checker_seen) << "no check worker was seen";
  EXPECT_EQ(crashed.status, 422) << crashed.body;
  EXPECT_NE(crashed.body.find("Duck.glb: checking it crashed the loader (SIGSEGV)"), std::string::npos) << crashed.body;
  auto again = c->Post("/v1/assets", items);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->status, 201) << again->body;
}

// A check that never ends (its worker stopped: it uses no CPU time, so its CPU limit never comes) is killed after twice
// that limit in wall time, and the upload is a 422 that says so.
TEST(Workers, AnUploadWhoseCheckNeverEndsIsRefusedInBoundedTime) {
  TempDir dir;
  std::vector<std::string> args = kArgs;
  args.insert(args.end(), {"--asset-check-cpu-s", "1"});
  Daemon daemon(dir.path() / "data", args);
  const auto start = std::chrono::steady_clock::now();
  const SignalledUpload stopped = upload_signalling_the_check(daemon, duck_upload(), SIGSTOP);
  const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(stopped.checker_seen) << "no check worker was seen";
  EXPECT_EQ(stopped.status, 422) << stopped.body;
  EXPECT_NE(stopped.body.find("checking it took more than 2 s"), std::string::npos) << stopped.body;
  EXPECT_LT(waited, 30) << "the upload waited " << waited << " s";
}

}  // namespace
}  // namespace tessera::server::test
