#include "tests/server/postgres_cluster.h"

#include <fcntl.h>
#include <pwd.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace tessera::server::test {

namespace {

namespace fs = std::filesystem;

constexpr const char* kDirPrefix = "tessera-pg-";
constexpr const char* kUnprivilegedUser = "nobody";

// Runs `argv` (searched in PATH), its stdout into `out` when given, its stderr (and stdout otherwise) appended to
// `log`; returns its exit status (-1 when it could not run).
int run(const std::vector<std::string>& argv, std::string* out, const fs::path& log) {
  int pipe_fds[2] = {-1, -1};
  if (out && pipe(pipe_fds) != 0) return -1;
  const pid_t pid = fork();
  if (pid < 0) return -1;
  if (pid == 0) {
    const int log_fd = open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (log_fd >= 0) {
      dup2(log_fd, 2);
      if (!out) dup2(log_fd, 1);
    }
    if (out) {
      dup2(pipe_fds[1], 1);
      close(pipe_fds[0]);
    }
    int devnull = open("/dev/null", O_RDONLY);
    if (devnull >= 0) dup2(devnull, 0);
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    execvp(args[0], args.data());
    _exit(127);
  }
  if (out) {
    close(pipe_fds[1]);
    char buf[4096];
    ssize_t n;
    while ((n = read(pipe_fds[0], buf, sizeof buf)) > 0 || (n < 0 && errno == EINTR))
      if (n > 0) out->append(buf, static_cast<size_t>(n));
    close(pipe_fds[0]);
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string tail(const fs::path& file, size_t bytes = 2000) {
  std::ifstream in(file, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  std::string s = ss.str();
  return s.size() > bytes ? s.substr(s.size() - bytes) : s;
}

// The server's binaries: TESSERA_PG_BINDIR, else the newest /usr/lib/postgresql/N/bin with initdb (Debian keeps
// them off PATH), else PATH's. Empty when there are none.
fs::path find_bindir() {
  if (const char* dir = std::getenv("TESSERA_PG_BINDIR"); dir && *dir)
    return fs::exists(fs::path(dir) / "initdb") ? fs::path(dir) : fs::path();
  int newest = -1;
  fs::path found;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator("/usr/lib/postgresql", ec)) {
    const std::string name = entry.path().filename().string();
    const int version = std::atoi(name.c_str());
    if (version > newest && fs::exists(entry.path() / "bin" / "initdb") && fs::exists(entry.path() / "bin/pg_ctl")) {
      newest = version;
      found = entry.path() / "bin";
    }
  }
  if (!found.empty()) return found;
  if (const char* path = std::getenv("PATH")) {
    std::stringstream ss(path);
    for (std::string dir; std::getline(ss, dir, ':');)
      if (!dir.empty() && fs::exists(fs::path(dir) / "initdb") && fs::exists(fs::path(dir) / "pg_ctl")) return dir;
  }
  return {};
}

// The server's commands run as `nobody` when the test runs as root (initdb and postgres refuse root).
std::vector<std::string> as_server_user(std::vector<std::string> argv) {
  if (geteuid() != 0) return argv;
  argv.insert(argv.begin(), {"runuser", "-u", kUnprivilegedUser, "--"});
  return argv;
}

// Clusters of test processes that died without stopping them (a crash, a timeout's SIGKILL): stopped and removed.
void remove_abandoned(const fs::path& bindir) {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(fs::temp_directory_path(), ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(kDirPrefix, 0) != 0) continue;
    const long owner = std::atol(name.c_str() + std::char_traits<char>::length(kDirPrefix));
    if (owner <= 0 || kill(static_cast<pid_t>(owner), 0) == 0 || errno != ESRCH) continue;
    if (fs::exists(entry.path() / "data" / "postmaster.pid"))
      run(as_server_user(
              {(bindir / "pg_ctl").string(), "-D", (entry.path() / "data").string(), "-m", "immediate", "-w", "stop"}),
          nullptr, "/dev/null");
    fs::remove_all(entry.path(), ec);
  }
}

}  // namespace

PostgresCluster::PostgresCluster() {
  bindir_ = find_bindir();
  if (bindir_.empty())
    throw std::runtime_error(
        "PostgreSQL's server programs (initdb, pg_ctl) were not found in /usr/lib/postgresql/*/bin, TESSERA_PG_BINDIR "
        "or PATH: install Debian's postgresql package (deploy/install-deps.sh test does)");
  remove_abandoned(bindir_);
  std::random_device rd;
  dir_ = fs::temp_directory_path() / (kDirPrefix + std::to_string(getpid()) + "-" + std::to_string(rd()));
  fs::create_directories(dir_);
  if (geteuid() == 0) {
    const passwd* pw = getpwnam(kUnprivilegedUser);
    if (!pw || chown(dir_.c_str(), pw->pw_uid, pw->pw_gid) != 0)
      throw std::runtime_error("cannot give " + dir_.string() + " to the user " + kUnprivilegedUser +
                               " that runs the test PostgreSQL server");
  }
  const fs::path log = dir_ / "setup.log";
  // No fsync: the cluster lives as long as the test (a restart() is a crash of the server, not of the machine).
  if (run(as_server_user({(bindir_ / "initdb").string(), "-D", (dir_ / "data").string(), "-U", "tessera",
                          "--auth=trust", "-E", "UTF8", "--locale=C", "--no-sync"}),
          nullptr, log) != 0) {
    const std::string why = tail(log);
    fs::remove_all(dir_);
    throw std::runtime_error("initdb failed: " + why);
  }
  start();
}

PostgresCluster::~PostgresCluster() {
  stop();
  std::error_code ec;
  fs::remove_all(dir_, ec);
}

PostgresCluster& PostgresCluster::shared() {
  static PostgresCluster cluster;
  return cluster;
}

void PostgresCluster::start() {
  const fs::path log = dir_ / "setup.log";
  if (run(as_server_user({(bindir_ / "pg_ctl").string(), "-D", (dir_ / "data").string(), "-w", "-t", "60", "-l",
                          (dir_ / "server.log").string(), "-o",
                          "-k " + dir_.string() + " -c listen_addresses= -c fsync=off -c max_connections=200",
                          "start"}),
          nullptr, log) != 0)
    throw std::runtime_error("the test PostgreSQL server did not start: " + tail(log) + tail(dir_ / "server.log"));
}

void PostgresCluster::stop() {
  run(as_server_user({(bindir_ / "pg_ctl").string(), "-D", (dir_ / "data").string(), "-m", "immediate", "-w", "stop"}),
      nullptr, dir_ / "setup.log");
}

void PostgresCluster::restart() {
  stop();
  start();
}

std::string PostgresCluster::uri(const std::string& database) const {
  return "postgresql:///" + database + "?host=" + dir_.string() + "&user=tessera";
}

std::string PostgresCluster::database_of(const std::string& uri) {
  const size_t start = std::string("postgresql:///").size();
  return uri.substr(start, uri.find('?') - start);
}

std::string PostgresCluster::psql(const std::string& database, const std::string& sql) const {
  std::string out;
  const fs::path log = dir_ / "psql.log";
  if (run({(bindir_ / "psql").string(), "-X", "-q", "-A", "-t", "-v", "ON_ERROR_STOP=1", "-h", dir_.string(), "-U",
           "tessera", "-d", database, "-c", sql},
          &out, log) != 0)
    throw std::runtime_error("psql failed on \"" + sql + "\": " + tail(log, 500));
  while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
  return out;
}

std::string PostgresCluster::create_database() {
  std::string name = "t";
  name += std::to_string(++databases_);
  psql("postgres", "CREATE DATABASE " + name);
  return uri(name);
}

}  // namespace tessera::server::test
