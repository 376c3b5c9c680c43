#include "server/jobs/worker_sandbox.h"

#include <fcntl.h>
#include <linux/landlock.h>
#include <seccomp.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace tessera::server {

std::vector<std::string> apply_limits(const SandboxLimits& limits) {
  std::vector<std::string> failed;
  auto set = [&](int resource, uint64_t value, const char* name) {
    const rlimit r{static_cast<rlim_t>(value), static_cast<rlim_t>(value)};
    if (setrlimit(resource, &r) != 0) failed.push_back(std::string(name) + ": " + std::strerror(errno));
  };
  set(RLIMIT_CORE, 0, "RLIMIT_CORE");
  if (limits.address_space) set(RLIMIT_AS, limits.address_space, "RLIMIT_AS");
  if (limits.open_files) set(RLIMIT_NOFILE, limits.open_files, "RLIMIT_NOFILE");
  if (limits.cpu_seconds) {
    // SIGXCPU at the soft limit, SIGKILL a second later.
    const rlimit r{static_cast<rlim_t>(limits.cpu_seconds), static_cast<rlim_t>(limits.cpu_seconds + 1)};
    if (setrlimit(RLIMIT_CPU, &r) != 0) failed.push_back(std::string("RLIMIT_CPU: ") + std::strerror(errno));
  }
  return failed;
}

void deny_network_and_exec() {
  scmp_filter_ctx ctx = seccomp_init(SCMP_ACT_ALLOW);
  if (!ctx) throw std::runtime_error("seccomp_init failed");
  int rc = seccomp_rule_add(ctx, SCMP_ACT_ERRNO(EACCES), SCMP_SYS(socket), 1, SCMP_A0(SCMP_CMP_NE, AF_UNIX));
  if (rc == 0)
    rc = seccomp_rule_add(ctx, SCMP_ACT_ERRNO(EACCES), SCMP_SYS(socketpair), 1, SCMP_A0(SCMP_CMP_NE, AF_UNIX));
  if (rc == 0) rc = seccomp_rule_add(ctx, SCMP_ACT_ERRNO(EACCES), SCMP_SYS(execve), 0);
  if (rc == 0) rc = seccomp_rule_add(ctx, SCMP_ACT_ERRNO(EACCES), SCMP_SYS(execveat), 0);
  if (rc == 0) rc = seccomp_rule_add(ctx, SCMP_ACT_ERRNO(EPERM), SCMP_SYS(ptrace), 0);
  // libseccomp sets no_new_privs before loading (SCMP_FLTATR_CTL_NNP, on by default), which lets an unprivileged
  // process install a filter.
  if (rc == 0) rc = seccomp_load(ctx);
  seccomp_release(ctx);
  if (rc != 0) throw std::runtime_error(std::string("cannot load the system-call filter: ") + std::strerror(-rc));
}

bool confine_writes(const std::filesystem::path& writable, std::string* why) {
  auto fail = [&](const std::string& reason) {
    if (why) *why = reason;
    return false;
  };
  const long abi = syscall(SYS_landlock_create_ruleset, nullptr, 0, LANDLOCK_CREATE_RULESET_VERSION);
  if (abi < 1) return fail(std::string("Landlock is not available: ") + std::strerror(errno));
  // What changes the file system, in the rights of the kernel's ABI version (Linux documentation,
  // userspace-api/landlock.rst): REFER from version 2, TRUNCATE from version 3.
  uint64_t writes = LANDLOCK_ACCESS_FS_WRITE_FILE | LANDLOCK_ACCESS_FS_REMOVE_DIR | LANDLOCK_ACCESS_FS_REMOVE_FILE |
                    LANDLOCK_ACCESS_FS_MAKE_CHAR | LANDLOCK_ACCESS_FS_MAKE_DIR | LANDLOCK_ACCESS_FS_MAKE_REG |
                    LANDLOCK_ACCESS_FS_MAKE_SOCK | LANDLOCK_ACCESS_FS_MAKE_FIFO | LANDLOCK_ACCESS_FS_MAKE_BLOCK |
                    LANDLOCK_ACCESS_FS_MAKE_SYM;
#ifdef LANDLOCK_ACCESS_FS_REFER
  if (abi >= 2) writes |= LANDLOCK_ACCESS_FS_REFER;
#endif
#ifdef LANDLOCK_ACCESS_FS_TRUNCATE
  if (abi >= 3) writes |= LANDLOCK_ACCESS_FS_TRUNCATE;
#endif
  landlock_ruleset_attr attr{};
  attr.handled_access_fs = writes;
  const int ruleset = static_cast<int>(syscall(SYS_landlock_create_ruleset, &attr, sizeof attr, 0));
  if (ruleset < 0) return fail(std::string("cannot create a Landlock ruleset: ") + std::strerror(errno));
  const int dir = open(writable.c_str(), O_PATH | O_CLOEXEC);
  if (dir < 0) {
    close(ruleset);
    return fail("cannot open " + writable.string() + ": " + std::strerror(errno));
  }
  landlock_path_beneath_attr beneath{};
  beneath.allowed_access = writes;
  beneath.parent_fd = dir;
  const long added = syscall(SYS_landlock_add_rule, ruleset, LANDLOCK_RULE_PATH_BENEATH, &beneath, 0);
  const int add_errno = errno;
  close(dir);
  if (added != 0) {
    close(ruleset);
    return fail(std::string("cannot add a Landlock rule: ") + std::strerror(add_errno));
  }
  if (prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0 || syscall(SYS_landlock_restrict_self, ruleset, 0) != 0) {
    const int e = errno;
    close(ruleset);
    return fail(std::string("cannot enter the Landlock ruleset: ") + std::strerror(e));
  }
  close(ruleset);
  return true;
}

}  // namespace tessera::server
