// One daemon per data directory and per port. A second tesserad on the data directory of a running one would take
// its running jobs for orphans and render them again; one on its port would share the port with it (SO_REUSEPORT)
// and take half of its requests. Both refuse to start: exit 1, saying who holds what.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "tests/integration/daemon.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

namespace fs = std::filesystem;

struct Exited {
  bool exited = false;  // false: still running after the timeout (then killed)
  int code = -1;
  std::string output;  // stdout and stderr
};

// Runs tesserad with `args` until it exits, for at most `timeout_s`.
Exited run_tesserad(const std::vector<std::string>& args, const fs::path& output_file, double timeout_s) {
  std::vector<std::string> all = {TESSERAD_PATH};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    FILE* out = std::fopen(output_file.c_str(), "w");
    if (out) {
      dup2(fileno(out), STDOUT_FILENO);
      dup2(fileno(out), STDERR_FILENO);
    }
    execv(argv[0], argv.data());
    _exit(127);
  }
  Exited result;
  int status = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < deadline) {
    if (waitpid(pid, &status, WNOHANG) == pid) {
      result.exited = true;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  if (!result.exited) {
    kill(pid, SIGKILL);
    waitpid(pid, &status, 0);
  }
  result.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  result.output = test::read_text(output_file);
  return result;
}

TEST(Ownership, ASecondDaemonOnTheSameDataDirectoryRefusesToStart) {
  test::TempDir dir;
  const fs::path data = dir.path() / "data";
  test::Daemon first(data, {});
  const Exited second = run_tesserad({"--listen", "127.0.0.1", "--port", "0", "--data-dir", data.string()},
                                     dir.path() / "second.out", 20);
  ASSERT_TRUE(second.exited) << "a second daemon started on the same data directory";
  EXPECT_EQ(second.code, 1) << second.output;
  EXPECT_NE(second.output.find("in use by another tesserad (process " + std::to_string(first.pid()) + ")"),
            std::string::npos)
      << second.output;
  EXPECT_EQ(second.output.find("listening on"), std::string::npos) << second.output;
  // The first one is untouched.
  auto res = first.client()->Get("/readyz");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);

  // Once it has stopped, however it stopped, the directory is free again.
  first.stop(SIGKILL);
  test::Daemon third(data, {});
  EXPECT_GT(third.port(), 0);
}

TEST(Ownership, ASecondDaemonOnTheSamePortRefusesToStart) {
  test::TempDir dir;
  test::Daemon first(dir.path() / "a", {});
  const Exited second = run_tesserad(
      {"--listen", "127.0.0.1", "--port", std::to_string(first.port()), "--data-dir", (dir.path() / "b").string()},
      dir.path() / "second.out", 20);
  ASSERT_TRUE(second.exited) << "a second daemon started on the port of the first";
  EXPECT_EQ(second.code, 1) << second.output;
  EXPECT_NE(second.output.find("cannot listen on 127.0.0.1 port " + std::to_string(first.port())), std::string::npos)
      << second.output;
  EXPECT_NE(second.output.find("Address already in use"), std::string::npos) << second.output;
}

}  // namespace
}  // namespace tessera::server
