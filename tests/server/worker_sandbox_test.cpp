// The confinement of a render worker (worker_sandbox.h), entered in a forked child, as a worker enters it: what the
// child may still do and what it may not.
#include "server/jobs/worker_sandbox.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cerrno>
#include <cstdlib>
#include <functional>
#include <new>

#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

// Runs `body` in a child process and returns its exit status (each check in `body` exits with its own code).
int in_child(const std::function<int()>& body) {
  const pid_t pid = fork();
  if (pid == 0) _exit(body());
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 200 + WTERMSIG(status);
}

bool opens_for_writing(const std::filesystem::path& p) {
  const int fd = open(p.c_str(), O_CREAT | O_WRONLY | O_CLOEXEC, 0600);
  if (fd < 0) return false;
  close(fd);
  return true;
}

TEST(WorkerSandbox, AWorkerHasNoNetworkAndStartsNoProgram) {
  const int status = in_child([] {
    deny_network_and_exec();
    const int inet = socket(AF_INET, SOCK_STREAM, 0);
    if (inet >= 0 || errno != EACCES) return 1;
    if (socket(AF_INET6, SOCK_DGRAM, 0) >= 0) return 2;
    const int local = socket(AF_UNIX, SOCK_STREAM, 0);  // the C library's own (name service) may use one
    if (local < 0) return 3;
    close(local);
    execl("/bin/true", "true", static_cast<char*>(nullptr));
    if (errno != EACCES) return 4;
    return 0;
  });
  EXPECT_EQ(status, 0) << "1, 2: a network socket opened; 3: a local socket refused; 4: a program started";
  // Outside the sandbox, the same network socket opens: the check above can fail.
  const int inet = socket(AF_INET, SOCK_STREAM, 0);
  EXPECT_GE(inet, 0);
  if (inet >= 0) close(inet);
}

TEST(WorkerSandbox, AWorkerWritesOnlyBeneathItsDataDirectory) {
  TempDir dir;
  const auto data = dir.path() / "data";
  const auto outside = dir.path() / "outside";
  std::filesystem::create_directories(data / "jobs");
  std::filesystem::create_directories(outside);
  std::string why;
  const int status = in_child([&] {
    if (!confine_writes(data, &why)) return 100;
    if (!opens_for_writing(data / "jobs" / "checkpoint.tmp")) return 1;
    if (rename((data / "jobs" / "checkpoint.tmp").c_str(), (data / "jobs" / "checkpoint").c_str()) != 0) return 2;
    if (opens_for_writing(outside / "stolen")) return 3;
    if (mkdir((outside / "made").c_str(), 0700) == 0) return 4;
    if (!std::filesystem::exists("/etc/hostname") && !std::filesystem::exists("/proc/self/stat")) return 5;
    return 0;
  });
  if (status == 100) GTEST_SKIP() << "this kernel has no Landlock: " << why;
  EXPECT_EQ(status, 0) << "1, 2: writing in the data directory refused; 3, 4: writing outside it allowed";
  EXPECT_FALSE(std::filesystem::exists(outside / "stolen"));
  EXPECT_TRUE(std::filesystem::exists(data / "jobs" / "checkpoint"));
}

TEST(WorkerSandbox, AnAllocationAboveTheAddressSpaceLimitIsRefused) {
  const int status = in_child([] {
    SandboxLimits limits;
    limits.address_space = 512ull << 20;
    if (!apply_limits(limits).empty()) return 1;
    try {
      // 1 GiB: more than the whole limit. A call of operator new itself, which the compiler may not leave out as it
      // may a new-expression whose memory is never used.
      void* block = ::operator new(1ull << 30);
      ::operator delete(block);
      return 2;
    } catch (const std::bad_alloc&) {
      return 0;
    }
  });
  EXPECT_EQ(status, 0) << "1: the limit was not set; 2: the allocation succeeded";
}

TEST(WorkerSandbox, AProcessPastItsCpuLimitIsStopped) {
  const int status = in_child([] {
    SandboxLimits limits;
    limits.cpu_seconds = 1;
    if (!apply_limits(limits).empty()) return 1;
    volatile uint64_t spin = 0;
    for (;;) spin = spin + 1;  // ends by SIGXCPU after a second of CPU time
  });
  EXPECT_EQ(status, 200 + SIGXCPU) << "1: the limit was not set";
}

}  // namespace
}  // namespace tessera::server::test
