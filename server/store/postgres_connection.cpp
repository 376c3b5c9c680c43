#include "server/store/postgres_connection.h"

#include <libpq-fe.h>

#include <charconv>
#include <cstdlib>
#include <string_view>

#include "server/store/job_store.h"

namespace tessera::server {

PgResult::~PgResult() {
  PQclear(r_);
}

int PgResult::rows() const {
  return PQntuples(r_);
}

int PgResult::affected() const {
  return std::atoi(PQcmdTuples(r_));
}

bool PgResult::is_null(int col) const {
  return PQgetisnull(r_, row_, col);
}

std::string PgResult::text(int col) const {
  return std::string(PQgetvalue(r_, row_, col), static_cast<size_t>(PQgetlength(r_, row_, col)));
}

int64_t PgResult::int64(int col) const {
  return std::strtoll(PQgetvalue(r_, row_, col), nullptr, 10);
}

double PgResult::real(int col) const {
  const char* p = PQgetvalue(r_, row_, col);
  double v = 0;
  std::from_chars(p, p + PQgetlength(r_, row_, col), v);
  return v;
}

PgConnection::~PgConnection() {
  PQfinish(conn_);
}

void PgConnection::close() {
  PQfinish(conn_);
  conn_ = nullptr;
}

void PgConnection::connect() {
  if (conn_ && PQstatus(conn_) == CONNECTION_OK) return;
  close();
  // The conninfo (a URI or key=value string) is expanded in place of dbname; the keys after it add to it.
  const char* keys[] = {"fallback_application_name", "dbname",           "keepalives", "keepalives_idle",
                        "keepalives_interval",       "keepalives_count", nullptr};
  const char* values[] = {application_name_.c_str(), conninfo_.c_str(), "1", "10", "5", "3", nullptr};
  conn_ = PQconnectdbParams(keys, values, 1);
  if (!conn_) throw JobStoreError("job store: cannot connect to PostgreSQL: out of memory", false);
  if (PQstatus(conn_) != CONNECTION_OK) {
    std::string msg = PQerrorMessage(conn_);
    while (!msg.empty() && msg.back() == '\n') msg.pop_back();
    close();
    throw JobStoreError("job store: cannot connect to PostgreSQL: " + msg, false);
  }
  // Notices (a table that exists already) are not news for the log.
  PQsetNoticeProcessor(
      conn_, [](void*, const char*) {}, nullptr);
  if (idle_transaction_limit_ms_ > 0) {
    const std::string set = "SET idle_in_transaction_session_timeout = " + std::to_string(idle_transaction_limit_ms_);
    PGresult* r = PQexec(conn_, set.c_str());
    const bool ok = r && PQresultStatus(r) == PGRES_COMMAND_OK;
    PQclear(r);
    if (!ok) {
      std::string msg = PQerrorMessage(conn_);
      while (!msg.empty() && msg.back() == '\n') msg.pop_back();
      close();
      throw JobStoreError("job store: cannot limit idle transactions: " + msg, false);
    }
  }
}

PgResult PgConnection::exec(const std::string& sql, const Params& params) {
  connect();
  std::vector<const char*> values;
  values.reserve(params.size());
  for (const auto& p : params) values.push_back(p ? p->c_str() : nullptr);
  PGresult* r = params.empty() ? PQexec(conn_, sql.c_str())
                               : PQexecParams(conn_, sql.c_str(), static_cast<int>(values.size()), nullptr,
                                              values.data(), nullptr, nullptr, 0);
  PgResult result(r);
  const ExecStatusType status = r ? PQresultStatus(r) : PGRES_FATAL_ERROR;
  if (status == PGRES_COMMAND_OK || status == PGRES_TUPLES_OK) return result;
  std::string msg = r ? PQresultErrorMessage(r) : PQerrorMessage(conn_);
  while (!msg.empty() && msg.back() == '\n') msg.pop_back();
  // Class 53, insufficient resources: 53100 is a full disk.
  const char* state = r ? PQresultErrorField(r, PG_DIAG_SQLSTATE) : nullptr;
  const std::string_view sqlstate = state ? state : "";
  const bool full = sqlstate == "53100";
  // A connection that broke (libpq's own error, with no SQLSTATE: the server went away, which libpq does not always
  // note in its status), or that the server ends (class 08, connection exception; 57, an operator's shutdown) is
  // opened again at the next call.
  if (PQstatus(conn_) != CONNECTION_OK || sqlstate.empty() || sqlstate.starts_with("08") || sqlstate.starts_with("57"))
    close();
  throw JobStoreError("job store: " + msg, full);
}

void PgConnection::exec_quietly(const std::string& sql) {
  if (conn_) PQclear(PQexec(conn_, sql.c_str()));
}

std::string pg_text(int64_t v) {
  return std::to_string(v);
}

// The shortest text that reads back as the same double (PostgreSQL parses it exactly).
std::string pg_text(double v) {
  char buf[64];
  auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return ec == std::errc() ? std::string(buf, end) : "0";
}

}  // namespace tessera::server
