#include "server/sqlite_job_store.h"

#include <sqlite3.h>

#include <stdexcept>

namespace tessera::server {

namespace {

constexpr const char* kColumns =
    "id, kind, state, priority, created_at, started_at, finished_at, settings, outputs, passes, samples_done, "
    "samples_total, elapsed_s, eta_s, samples_per_s, stop_reason, error";

[[noreturn]] void fail(sqlite3* db, const std::string& what) {
  throw std::runtime_error("job store: " + what + ": " + (db ? sqlite3_errmsg(db) : "out of memory"));
}

}  // namespace

// A prepared statement with bound parameters (never values spliced into SQL), finalized on destruction. Prepared per
// call: next to a disk write the cost is small, and no statement outlives the lock that guards the connection.
class SqliteJobStore::Statement {
 public:
  Statement(sqlite3* db, const std::string& sql) : db_(db) {
    if (sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt_, nullptr) != SQLITE_OK) fail(db, "prepare");
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  void bind(int i, const std::string& v) {
    check(sqlite3_bind_text(stmt_, i, v.data(), static_cast<int>(v.size()), SQLITE_TRANSIENT));
  }
  void bind(int i, int64_t v) { check(sqlite3_bind_int64(stmt_, i, v)); }
  void bind(int i, double v) { check(sqlite3_bind_double(stmt_, i, v)); }
  void bind_null(int i) { check(sqlite3_bind_null(stmt_, i)); }
  void bind_optional(int i, const std::optional<double>& v) { v ? bind(i, *v) : bind_null(i); }
  void bind_text_or_null(int i, const std::string& v) { v.empty() ? bind_null(i) : bind(i, v); }

  // true: a row is available.
  bool step() {
    int rc = sqlite3_step(stmt_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    fail(db_, "step");
  }
  int64_t int64(int col) const { return sqlite3_column_int64(stmt_, col); }
  double real(int col) const { return sqlite3_column_double(stmt_, col); }
  bool is_null(int col) const { return sqlite3_column_type(stmt_, col) == SQLITE_NULL; }
  std::string text(int col) const {
    const unsigned char* p = sqlite3_column_text(stmt_, col);
    return p ? std::string(reinterpret_cast<const char*>(p), static_cast<size_t>(sqlite3_column_bytes(stmt_, col)))
             : std::string();
  }

  // Reads the columns of kColumns (and the document after them when asked).
  JobRecord record(bool with_document) const {
    JobRecord r;
    r.id = text(0);
    r.kind = text(1);
    r.state = parse_job_state(text(2)).value_or(JobState::kFailed);
    r.priority = static_cast<int>(int64(3));
    r.created_at_ms = int64(4);
    if (!is_null(5)) r.started_at_ms = int64(5);
    if (!is_null(6)) r.finished_at_ms = int64(6);
    r.settings = text(7);
    r.outputs = text(8);
    r.progress.passes = static_cast<uint32_t>(int64(9));
    r.progress.samples_done = static_cast<uint32_t>(int64(10));
    r.progress.samples_total = static_cast<uint32_t>(int64(11));
    r.progress.elapsed_s = real(12);
    if (!is_null(13)) r.progress.eta_s = real(13);
    r.progress.samples_per_s = real(14);
    r.stop_reason = text(15);
    r.error = text(16);
    if (with_document) r.document = text(17);
    return r;
  }

 private:
  void check(int rc) {
    if (rc != SQLITE_OK) fail(db_, "bind");
  }
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
};

SqliteJobStore::SqliteJobStore(const std::filesystem::path& file) {
  if (sqlite3_open_v2(file.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, nullptr) !=
      SQLITE_OK) {
    std::string msg = db_ ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close(db_);
    db_ = nullptr;
    throw std::runtime_error("job store: cannot open " + file.string() + ": " + msg);
  }
  try {
    // Another process (a second daemon by mistake, a backup) may hold the lock briefly: wait rather than fail.
    sqlite3_busy_timeout(db_, 5000);
    exec("PRAGMA journal_mode=WAL");
    // In WAL mode NORMAL loses no committed transaction on a process crash, only on power loss.
    exec("PRAGMA synchronous=NORMAL");
    exec("PRAGMA foreign_keys=ON");
    migrate();
  } catch (...) {
    sqlite3_close(db_);
    db_ = nullptr;
    throw;
  }
}

SqliteJobStore::~SqliteJobStore() {
  sqlite3_close(db_);
}

void SqliteJobStore::exec(const char* sql) {
  char* err = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &err) != SQLITE_OK) {
    std::string msg = err ? err : "unknown error";
    sqlite3_free(err);
    throw std::runtime_error(std::string("job store: ") + msg + " in: " + sql);
  }
}

void SqliteJobStore::migrate() {
  exec("BEGIN IMMEDIATE");
  try {
    exec("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)");
    int version = 0;
    {
      Statement s(db_, "SELECT MAX(version) FROM schema_version");
      if (s.step() && !s.is_null(0)) version = static_cast<int>(s.int64(0));
    }
    if (version > kSchemaVersion) {
      throw std::runtime_error("job store: the database has schema version " + std::to_string(version) +
                               ", newer than this daemon's " + std::to_string(kSchemaVersion));
    }
    if (version < 1) {
      exec(R"sql(
        CREATE TABLE jobs (
          seq INTEGER PRIMARY KEY AUTOINCREMENT,  -- submission order: first come, first served
          id TEXT NOT NULL UNIQUE,
          kind TEXT NOT NULL,
          state TEXT NOT NULL CHECK (state IN ('queued','running','succeeded','failed','cancelled')),
          priority INTEGER NOT NULL DEFAULT 0,
          created_at INTEGER NOT NULL,
          started_at INTEGER,
          finished_at INTEGER,
          document TEXT NOT NULL,
          settings TEXT NOT NULL,
          outputs TEXT NOT NULL,
          passes INTEGER NOT NULL DEFAULT 0,
          samples_done INTEGER NOT NULL DEFAULT 0,
          samples_total INTEGER NOT NULL DEFAULT 0,
          elapsed_s REAL NOT NULL DEFAULT 0,
          eta_s REAL,
          samples_per_s REAL NOT NULL DEFAULT 0,
          stop_reason TEXT,
          error TEXT
        );
        CREATE INDEX jobs_queue ON jobs (state, priority DESC, seq);
        INSERT INTO schema_version (version) VALUES (1);
      )sql");
    }
    exec("COMMIT");
  } catch (...) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    throw;
  }
}

void SqliteJobStore::create(const JobRecord& job) {
  std::lock_guard lock(mutex_);
  Statement s(db_,
              "INSERT INTO jobs (id, kind, state, priority, created_at, document, settings, outputs, samples_total) "
              "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)");
  s.bind(1, job.id);
  s.bind(2, job.kind);
  s.bind(3, std::string(job_state_name(JobState::kQueued)));
  s.bind(4, static_cast<int64_t>(job.priority));
  s.bind(5, job.created_at_ms);
  s.bind(6, job.document);
  s.bind(7, job.settings);
  s.bind(8, job.outputs);
  s.bind(9, static_cast<int64_t>(job.progress.samples_total));
  s.step();
}

std::optional<JobRecord> SqliteJobStore::claim_next(int64_t now_ms) {
  std::lock_guard lock(mutex_);
  // One statement, so two daemons sharing the file can never claim the same job.
  Statement s(db_, std::string("UPDATE jobs SET state = 'running', started_at = ?1, passes = 0, samples_done = 0, "
                               "elapsed_s = 0, eta_s = NULL, samples_per_s = 0 "
                               "WHERE seq = (SELECT seq FROM jobs WHERE state = 'queued' "
                               "ORDER BY priority DESC, seq LIMIT 1) RETURNING ") +
                       kColumns + ", document");
  s.bind(1, now_ms);
  if (!s.step()) return std::nullopt;
  JobRecord r = s.record(true);
  while (s.step()) {
  }
  return r;
}

void SqliteJobStore::update_progress(const std::string& id, const JobProgress& p) {
  std::lock_guard lock(mutex_);
  Statement s(db_,
              "UPDATE jobs SET passes = ?2, samples_done = ?3, samples_total = ?4, elapsed_s = ?5, eta_s = ?6, "
              "samples_per_s = ?7 WHERE id = ?1 AND state = 'running'");
  s.bind(1, id);
  s.bind(2, static_cast<int64_t>(p.passes));
  s.bind(3, static_cast<int64_t>(p.samples_done));
  s.bind(4, static_cast<int64_t>(p.samples_total));
  s.bind(5, p.elapsed_s);
  s.bind_optional(6, p.eta_s);
  s.bind(7, p.samples_per_s);
  s.step();
}

bool SqliteJobStore::transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                                const std::string& error) {
  std::lock_guard lock(mutex_);
  // The states this move is allowed from, as decided by the one state machine.
  std::string from_states;
  for (JobState s :
       {JobState::kQueued, JobState::kRunning, JobState::kSucceeded, JobState::kFailed, JobState::kCancelled}) {
    if (!can_transition(s, to)) continue;
    if (!from_states.empty()) from_states += ",";
    from_states += std::string("'") + job_state_name(s) + "'";
  }
  if (from_states.empty()) return false;
  std::string sql;
  if (to == JobState::kQueued) {
    sql =
        "UPDATE jobs SET state = 'queued', started_at = NULL, passes = 0, samples_done = 0, elapsed_s = 0, "
        "eta_s = NULL, samples_per_s = 0 WHERE id = ?1 AND state IN (" +
        from_states + ")";
  } else if (to == JobState::kRunning) {
    sql = "UPDATE jobs SET state = 'running', started_at = ?2 WHERE id = ?1 AND state IN (" + from_states + ")";
  } else {
    sql =
        "UPDATE jobs SET state = ?3, finished_at = ?2, stop_reason = ?4, error = ?5, "
        "eta_s = CASE WHEN ?3 = 'succeeded' THEN 0 ELSE eta_s END WHERE id = ?1 AND state IN (" +
        from_states + ")";
  }
  Statement s(db_, sql);
  s.bind(1, id);
  if (to != JobState::kQueued) s.bind(2, now_ms);
  if (is_terminal(to)) {
    s.bind(3, std::string(job_state_name(to)));
    s.bind_text_or_null(4, stop_reason);
    s.bind_text_or_null(5, error);
  }
  s.step();
  return sqlite3_changes(db_) > 0;
}

std::optional<JobRecord> SqliteJobStore::get(const std::string& id, bool with_document) {
  std::lock_guard lock(mutex_);
  Statement s(db_,
              std::string("SELECT ") + kColumns + (with_document ? ", document" : "") + " FROM jobs WHERE id = ?1");
  s.bind(1, id);
  if (!s.step()) return std::nullopt;
  return s.record(with_document);
}

std::vector<JobRecord> SqliteJobStore::list(const JobFilter& filter) {
  std::lock_guard lock(mutex_);
  Statement s(db_, std::string("SELECT ") + kColumns + " FROM jobs" + (filter.state ? " WHERE state = ?1" : "") +
                       " ORDER BY seq DESC LIMIT ?2");
  if (filter.state) s.bind(1, std::string(job_state_name(*filter.state)));
  s.bind(2, static_cast<int64_t>(filter.limit));
  std::vector<JobRecord> out;
  while (s.step()) out.push_back(s.record(false));
  return out;
}

bool SqliteJobStore::remove(const std::string& id) {
  std::lock_guard lock(mutex_);
  Statement s(db_, "DELETE FROM jobs WHERE id = ?1");
  s.bind(1, id);
  s.step();
  return sqlite3_changes(db_) > 0;
}

int SqliteJobStore::requeue_running() {
  std::lock_guard lock(mutex_);
  Statement s(db_,
              "UPDATE jobs SET state = 'queued', started_at = NULL, passes = 0, samples_done = 0, elapsed_s = 0, "
              "eta_s = NULL, samples_per_s = 0 WHERE state = 'running'");
  s.step();
  return sqlite3_changes(db_);
}

}  // namespace tessera::server
