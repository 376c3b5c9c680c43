// A throw-away PostgreSQL server for a test process: initdb in a fresh directory under the system temp dir, the server
// listening on a Unix socket in that directory only (no TCP port), trust authentication for the one role `tessera`,
// stopped and removed with the object. The server refuses to run as root, so a test run as root starts it as
// `nobody` (runuser). The binaries are Debian's postgresql package's (/usr/lib/postgresql/N/bin, the newest N), or
// TESSERA_PG_BINDIR's; when there are none the constructor throws, naming the package, so that a test using it fails
// rather than being skipped.
#pragma once

#include <filesystem>
#include <string>

namespace tessera::server::test {

class PostgresCluster {
 public:
  PostgresCluster();
  ~PostgresCluster();
  PostgresCluster(const PostgresCluster&) = delete;
  PostgresCluster& operator=(const PostgresCluster&) = delete;

  // One cluster per test process, started at the first call, stopped at exit.
  static PostgresCluster& shared();

  // A new empty database; its libpq connection URI (postgresql:///NAME?host=SOCKET_DIR&user=tessera).
  std::string create_database();
  std::string uri(const std::string& database) const;
  // The database a URI of uri() names.
  static std::string database_of(const std::string& uri);
  // Runs SQL through psql on `database` (as the superuser); its output (unaligned, tuples only). Throws on failure.
  std::string psql(const std::string& database, const std::string& sql) const;
  // Stops the server (immediate: as a crash would) and starts it again on the same socket.
  void restart();
  const std::filesystem::path& socket_dir() const { return dir_; }

 private:
  void start();
  void stop();

  std::filesystem::path bindir_;
  std::filesystem::path dir_;  // the socket, the log; data/ inside
  int databases_ = 0;
};

}  // namespace tessera::server::test
