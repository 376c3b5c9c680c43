// A tesserad process for a test: started on port 0 with a given data directory, its "listening on" line read, its
// stderr (JSON logs) kept in a file beside the data directory, stopped with a signal.
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <httplib.h>
#include <nlohmann/json.hpp>

namespace tessera::server::test {

class Daemon {
 public:
  Daemon(const std::filesystem::path& data_dir, const std::vector<std::string>& extra_args);
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  int port() const { return port_; }
  pid_t pid() const { return pid_; }
  std::unique_ptr<httplib::Client> client() const;
  // Sends `signal` and waits; returns the exit status (or 128 + signal when killed).
  int stop(int signal);
  std::string log() const;

 private:
  pid_t pid_ = -1;
  int stdout_fd_ = -1;
  int port_ = 0;
  std::filesystem::path log_path_;
};

}  // namespace tessera::server::test
