// The confinement a render worker enters before it reads a scene (worker_process.h): resource limits, a system-call
// filter and a file-system rule, each of which an unprivileged process may set on itself and none of which it can
// lift again.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace tessera::server {

struct SandboxLimits {
  uint64_t address_space = 0;  // RLIMIT_AS in bytes; 0: not limited
  uint64_t open_files = 0;     // RLIMIT_NOFILE; 0: as inherited
  uint64_t cpu_seconds = 0;    // RLIMIT_CPU; 0: not limited
};

// Resource limits (setrlimit; core dumps off: a crashing scene leaves no core of another user's data). Returns what
// could not be set, for the log.
std::vector<std::string> apply_limits(const SandboxLimits& limits);

// No network and no new programs: socket() of any family but AF_UNIX, execve() and execveat() fail with EACCES, and
// ptrace() with EPERM (seccomp, through libseccomp; no_new_privs set). Throws std::runtime_error when the filter
// cannot be loaded.
void deny_network_and_exec();

// Writes (creating, writing, renaming, removing files and folders) only beneath `writable`: Landlock (Linux 5.13 and
// later), which needs no privilege. Reading is left as it is. Returns false, with the reason, where the kernel has no
// Landlock (the worker then runs without this rule; the daemon says so in its log).
bool confine_writes(const std::filesystem::path& writable, std::string* why);

}  // namespace tessera::server
