// One libpq connection to PostgreSQL and the results of its statements, for what the daemon keeps in PostgreSQL (the
// job store, the event bus). A connection that broke (the server restarted, was shut down or went away) is opened
// again at the next statement, the statement that found it broken failing with JobStoreError, as every error does.
// Not thread-safe: each user holds its own connection behind its own mutex.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

struct pg_conn;
struct pg_result;

namespace tessera::server {

// The result of one statement, freed with the object.
class PgResult {
 public:
  explicit PgResult(pg_result* r) : r_(r) {}
  ~PgResult();
  PgResult(PgResult&& o) noexcept : r_(o.r_), row_(o.row_) { o.r_ = nullptr; }
  PgResult(const PgResult&) = delete;
  PgResult& operator=(const PgResult&) = delete;

  int rows() const;
  // The number of rows an UPDATE or DELETE changed.
  int affected() const;
  // Reads go to this row from here on.
  PgResult& at(int row) {
    row_ = row;
    return *this;
  }
  bool is_null(int col) const;
  std::string text(int col) const;
  int64_t int64(int col) const;
  double real(int col) const;

 private:
  pg_result* r_;
  int row_ = 0;
};

class PgConnection {
 public:
  using Params = std::vector<std::optional<std::string>>;

  // Connects at the first statement (or connect()). TCP keepalives are on, so that a server that vanished without
  // closing the connection is noticed within about half a minute. `application_name` names the connection in the
  // server's pg_stat_activity ("tesserad NODE notifications"), unless the conninfo names it.
  //
  // `idle_transaction_limit_ms` (0: the server's setting) is the session's idle_in_transaction_session_timeout: a
  // process stopped between BEGIN and COMMIT (frozen by SIGSTOP, a debugger, a paused VM) would otherwise hold its row
  // locks for as long as it is stopped, and every other node that writes those rows waits behind it. Past the limit
  // the server ends the session and rolls its transaction back (PostgreSQL 15 manual, §20.11.1); the stopped process
  // finds its connection closed when it runs again, and its statement fails as any lost connection's does.
  explicit PgConnection(std::string conninfo, std::string application_name = "tesserad",
                        int64_t idle_transaction_limit_ms = 0)
      : conninfo_(std::move(conninfo)),
        application_name_(std::move(application_name)),
        idle_transaction_limit_ms_(idle_transaction_limit_ms) {}
  ~PgConnection();
  PgConnection(const PgConnection&) = delete;
  PgConnection& operator=(const PgConnection&) = delete;

  // Opens the connection unless it is open; throws JobStoreError when it cannot.
  void connect();
  // Runs one statement with text parameters ($1, $2, ...; nullopt is NULL); throws JobStoreError on failure.
  PgResult exec(const std::string& sql, const Params& params = {});
  // Runs a statement whose failure needs no report (a ROLLBACK after a failure), if the connection is open.
  void exec_quietly(const std::string& sql);
  // The connection itself (LISTEN reads its socket), null while closed.
  pg_conn* raw() const { return conn_; }
  // Closes the connection; the next statement opens it again.
  void close();

 private:
  std::string conninfo_;
  std::string application_name_;
  int64_t idle_transaction_limit_ms_;
  pg_conn* conn_ = nullptr;
};

// The text PostgreSQL reads back as the same number.
std::string pg_text(int64_t v);
std::string pg_text(double v);

}  // namespace tessera::server
