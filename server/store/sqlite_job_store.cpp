#include "server/store/sqlite_job_store.h"

#include <sqlite3.h>

#include <cerrno>

#include "server/base/file_io.h"
#include "server/store/job_store_sql.h"

namespace tessera::server {

namespace {

// The jobs table as of schema version 2 (paused state, owner, warnings, idempotency keys).
constexpr const char* kJobsTableV2 = R"sql(
  CREATE TABLE jobs (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,  -- submission order: first come, first served
    id TEXT NOT NULL UNIQUE,
    kind TEXT NOT NULL,
    state TEXT NOT NULL CHECK (state IN ('queued','running','paused','succeeded','failed','cancelled')),
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
    error TEXT,
    owner TEXT NOT NULL DEFAULT '',
    warnings TEXT NOT NULL DEFAULT '[]',
    idempotency_key TEXT,
    request_hash TEXT
  );
)sql";

// SQLite says SQLITE_FULL when a write comes short (ENOSPC, or a file-size limit reached midway); a write refused
// outright with another errno (EDQUOT, EFBIG) is an I/O error, and only the errno tells. sqlite3_system_errno() is
// not kept on every path (a failed WAL append leaves it 0), so the errno the failed call left is read instead: every
// call that may do I/O is preceded by errno = 0, so a value here comes from that call.
bool out_of_space(sqlite3* db, int os_error) {
  if (!db) return false;
  const int primary = sqlite3_extended_errcode(db) & 0xff;
  return primary == SQLITE_FULL || (primary == SQLITE_IOERR && is_out_of_space(os_error));
}

// Right after the call that failed, before anything else can touch errno.
[[noreturn]] void fail(sqlite3* db, const std::string& what) {
  const int os_error = errno;
  throw JobStoreError("job store: " + what + ": " + (db ? sqlite3_errmsg(db) : "out of memory"),
                      out_of_space(db, os_error));
}

}  // namespace

// A prepared statement with bound parameters (never values spliced into SQL), used under the lock that guards the
// connection. Each SQL text is prepared once and kept: for a small read, preparing cost more than the lookup (most of
// the daemon's time on a status request was SQLite's parser). Destruction resets the statement (it holds no read or
// write open) and hands it back; a nested use of the same text, or one beyond the cache's size, gets its own.
class SqliteJobStore::Statement {
 public:
  Statement(SqliteJobStore& store, const std::string& sql) : db_(store.db_) {
    errno = 0;  // see fail()
    auto it = store.statements_.find(sql);
    if (it == store.statements_.end() && store.statements_.size() < kMaxCachedStatements) {
      if (sqlite3_prepare_v3(db_, sql.c_str(), -1, SQLITE_PREPARE_PERSISTENT, &stmt_, nullptr) != SQLITE_OK)
        fail(db_, "prepare");
      it = store.statements_.emplace(sql, CachedStatement{stmt_, false}).first;
    }
    if (it != store.statements_.end() && !it->second.in_use) {
      cached_ = &it->second;  // elements of an unordered_map keep their address when it grows
      cached_->in_use = true;
      stmt_ = cached_->stmt;
    } else if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &stmt_, nullptr) != SQLITE_OK) {
      fail(db_, "prepare");
    }
  }
  ~Statement() {
    if (!cached_) {
      sqlite3_finalize(stmt_);
      return;
    }
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
    cached_->in_use = false;
  }
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
    errno = 0;  // see fail()
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

  JobRecord record(bool with_document) const { return read_job_record(*this, with_document); }

 private:
  void check(int rc) {
    if (rc != SQLITE_OK) fail(db_, "bind");
  }
  // Distinct SQL texts are few (the statements below, with the state lists of transition() and list()).
  static constexpr size_t kMaxCachedStatements = 256;
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
  CachedStatement* cached_ = nullptr;
};

SqliteJobStore::SqliteJobStore(const std::filesystem::path& file) {
  errno = 0;  // see fail()
  if (sqlite3_open_v2(file.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, nullptr) !=
      SQLITE_OK) {
    const bool full = out_of_space(db_, errno);
    std::string msg = db_ ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close(db_);
    db_ = nullptr;
    throw JobStoreError("job store: cannot open " + file.string() + ": " + msg, full);
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
    close();
    throw;
  }
}

SqliteJobStore::~SqliteJobStore() {
  close();
}

void SqliteJobStore::close() {
  // sqlite3_close() refuses a connection with unfinalized statements.
  for (auto& [sql, cached] : statements_) sqlite3_finalize(cached.stmt);
  statements_.clear();
  // _v2: should a statement still be open, the connection is closed when it is finalized instead of leaking.
  sqlite3_close_v2(db_);
  db_ = nullptr;
}

void SqliteJobStore::exec(const char* sql) {
  char* err = nullptr;
  errno = 0;  // see fail()
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &err) != SQLITE_OK) {
    const bool full = out_of_space(db_, errno);
    std::string msg = err ? err : "unknown error";
    sqlite3_free(err);
    throw JobStoreError(std::string("job store: ") + msg + " in: " + sql, full);
  }
}

void SqliteJobStore::migrate() {
  exec("BEGIN IMMEDIATE");
  try {
    exec("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)");
    int version = 0;
    {
      Statement s(*this, "SELECT MAX(version) FROM schema_version");
      if (s.step() && !s.is_null(0)) version = static_cast<int>(s.int64(0));
    }
    if (version > kSchemaVersion) {
      throw JobStoreError("job store: the database has schema version " + std::to_string(version) +
                              ", newer than this daemon's " + std::to_string(kSchemaVersion),
                          false);
    }
    if (version < 1) {
      exec(kJobsTableV2);
    } else if (version < 2) {
      // Version 1 lacked the paused state (a CHECK constraint: the table is rebuilt) and the owner, warnings and
      // idempotency-key columns.
      exec("ALTER TABLE jobs RENAME TO jobs_v1");
      exec("DROP INDEX IF EXISTS jobs_queue");
      exec(kJobsTableV2);
      exec(
          "INSERT INTO jobs (seq, id, kind, state, priority, created_at, started_at, finished_at, document, settings, "
          "outputs, passes, samples_done, samples_total, elapsed_s, eta_s, samples_per_s, stop_reason, error) "
          "SELECT seq, id, kind, state, priority, created_at, started_at, finished_at, document, settings, outputs, "
          "passes, samples_done, samples_total, elapsed_s, eta_s, samples_per_s, stop_reason, error FROM jobs_v1");
      exec("DROP TABLE jobs_v1");
    }
    if (version < 2) {
      exec("CREATE INDEX jobs_queue ON jobs (state, priority DESC, seq)");
      exec("CREATE INDEX jobs_owner ON jobs (owner, seq)");
      exec("CREATE UNIQUE INDEX jobs_idempotency ON jobs (owner, idempotency_key) WHERE idempotency_key IS NOT NULL");
      exec("INSERT INTO schema_version (version) VALUES (2)");
    }
    if (version < 3) {
      // Version 3: jobs have a name; older jobs keep an empty one.
      exec("ALTER TABLE jobs ADD COLUMN name TEXT NOT NULL DEFAULT ''");
      exec("INSERT INTO schema_version (version) VALUES (3)");
    }
    if (version < 4) {
      // Version 4: the lease of a run (JobRecord::epoch); a job left running by a version 3 daemon has none, and
      // requeue_running() puts it back at the start.
      exec("ALTER TABLE jobs ADD COLUMN epoch INTEGER NOT NULL DEFAULT 0");
      exec("ALTER TABLE jobs ADD COLUMN lease_expires_at INTEGER");
      exec("ALTER TABLE jobs ADD COLUMN node TEXT NOT NULL DEFAULT ''");
      exec("INSERT INTO schema_version (version) VALUES (4)");
    }
    if (version < 5) {
      // Version 5: the runs of a job that were lost (JobRecord::lost_runs).
      exec("ALTER TABLE jobs ADD COLUMN lost_runs INTEGER NOT NULL DEFAULT 0");
      exec("INSERT INTO schema_version (version) VALUES (5)");
    }
    exec("COMMIT");
  } catch (...) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    throw;
  }
}

void SqliteJobStore::create(const JobRecord& job) {
  std::lock_guard lock(mutex_);
  Statement s(*this,
              "INSERT INTO jobs (id, kind, state, priority, created_at, document, settings, outputs, samples_total, "
              "owner, warnings, idempotency_key, request_hash, name) "
              "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14)");
  s.bind(1, job.id);
  s.bind(2, job.kind);
  s.bind(3, std::string(job_state_name(JobState::kQueued)));
  s.bind(4, static_cast<int64_t>(job.priority));
  s.bind(5, job.created_at_ms);
  s.bind(6, job.document);
  s.bind(7, job.settings);
  s.bind(8, job.outputs);
  s.bind(9, static_cast<int64_t>(job.progress.samples_total));
  s.bind(10, job.owner);
  s.bind(11, job.warnings.empty() ? std::string("[]") : job.warnings);
  s.bind_text_or_null(12, job.idempotency_key);
  s.bind_text_or_null(13, job.request_hash);
  s.bind(14, job.name);
  s.step();
}

std::optional<JobRecord> SqliteJobStore::claim_next(int64_t now_ms, int64_t lease_ms, int max_running_per_owner) {
  std::lock_guard lock(mutex_);
  // One statement, so two daemons sharing the file can never claim the same job, nor an owner's runs pass the cap
  // (the write lock serialises the statements).
  Statement s(*this,
              std::string("UPDATE jobs SET state = 'running', started_at = ?1, passes = 0, samples_done = 0, "
                          "elapsed_s = 0, eta_s = NULL, samples_per_s = 0, epoch = epoch + 1, "
                          "lease_expires_at = ?1 + ?2, lost_runs = lost_runs + (state = 'running') "
                          "WHERE seq = (SELECT seq FROM jobs c WHERE (c.state = 'queued' OR (c.state = 'running' "
                          "AND c.lease_expires_at < ?1)) AND (?3 <= 0 OR (SELECT count(*) FROM jobs r WHERE "
                          "r.owner = c.owner AND r.state = 'running' AND r.lease_expires_at >= ?1) < ?3) "
                          "ORDER BY c.priority DESC, c.seq LIMIT 1) RETURNING ") +
                  kJobColumns + ", document");
  s.bind(1, now_ms);
  s.bind(2, lease_ms);
  s.bind(3, static_cast<int64_t>(max_running_per_owner));
  if (!s.step()) return std::nullopt;
  JobRecord r = s.record(true);
  while (s.step()) {
  }
  return r;
}

bool SqliteJobStore::renew_lease(const std::string& id, int64_t epoch, int64_t now_ms, int64_t lease_ms) {
  std::lock_guard lock(mutex_);
  Statement s(*this, "UPDATE jobs SET lease_expires_at = ?3 + ?4 WHERE id = ?1 AND state = 'running' AND epoch = ?2");
  s.bind(1, id);
  s.bind(2, epoch);
  s.bind(3, now_ms);
  s.bind(4, lease_ms);
  s.step();
  return sqlite3_changes(db_) > 0;
}

bool SqliteJobStore::update_progress(const std::string& id, int64_t epoch, const JobProgress& p) {
  std::lock_guard lock(mutex_);
  Statement s(*this,
              "UPDATE jobs SET passes = ?2, samples_done = ?3, samples_total = ?4, elapsed_s = ?5, eta_s = ?6, "
              "samples_per_s = ?7 WHERE id = ?1 AND state = 'running' AND epoch = ?8");
  s.bind(1, id);
  s.bind(2, static_cast<int64_t>(p.passes));
  s.bind(3, static_cast<int64_t>(p.samples_done));
  s.bind(4, static_cast<int64_t>(p.samples_total));
  s.bind(5, p.elapsed_s);
  s.bind_optional(6, p.eta_s);
  s.bind(7, p.samples_per_s);
  s.bind(8, epoch);
  s.step();
  return sqlite3_changes(db_) > 0;
}

bool SqliteJobStore::transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                                const std::string& error, std::optional<JobState> only_from) {
  std::lock_guard lock(mutex_);
  return move(id, to, now_ms, stop_reason, error, sql_states_into(to, only_from), std::nullopt);
}

bool SqliteJobStore::end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms,
                             const std::string& stop_reason, const std::string& error) {
  std::lock_guard lock(mutex_);
  return move(id, to, now_ms, stop_reason, error, sql_states_into(to, JobState::kRunning), epoch);
}

bool SqliteJobStore::move(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                          const std::string& error, const std::string& from_states, std::optional<int64_t> epoch) {
  if (from_states.empty()) return false;
  // Out of running, the lease ends with the run.
  const std::string where = " WHERE id = ?1 AND state IN (" + from_states + ")" + (epoch ? " AND epoch = ?6" : "");
  std::string sql;
  if (to == JobState::kQueued) {
    sql =
        "UPDATE jobs SET state = 'queued', started_at = NULL, finished_at = NULL, stop_reason = NULL, error = NULL, "
        "passes = 0, samples_done = 0, elapsed_s = 0, eta_s = NULL, samples_per_s = 0, lease_expires_at = NULL, "
        "node = '', lost_runs = CASE WHEN state IN (" +
        sql_terminal_states() + ") THEN 0 ELSE lost_runs END" + where;
  } else if (to == JobState::kRunning) {
    sql = "UPDATE jobs SET state = 'running', started_at = ?2" + where;
  } else if (to == JobState::kPaused) {
    sql = "UPDATE jobs SET state = 'paused', eta_s = NULL, lease_expires_at = NULL, node = ''" + where;
  } else {
    sql =
        "UPDATE jobs SET state = ?3, finished_at = ?2, stop_reason = ?4, error = ?5, lease_expires_at = NULL, "
        "node = '', eta_s = CASE WHEN ?3 = 'succeeded' THEN 0 ELSE eta_s END" +
        where;
  }
  Statement s(*this, sql);
  s.bind(1, id);
  if (to == JobState::kRunning || is_terminal(to)) s.bind(2, now_ms);
  if (is_terminal(to)) {
    s.bind(3, std::string(job_state_name(to)));
    s.bind_text_or_null(4, stop_reason);
    s.bind_text_or_null(5, error);
  }
  if (epoch) s.bind(6, *epoch);
  s.step();
  return sqlite3_changes(db_) > 0;
}

bool SqliteJobStore::set_priority(const std::string& id, int priority) {
  std::lock_guard lock(mutex_);
  Statement s(*this, "UPDATE jobs SET priority = ?2 WHERE id = ?1 AND state IN (" +
                         sql_state_list(action_states(JobAction::kPriority)) + ")");
  s.bind(1, id);
  s.bind(2, static_cast<int64_t>(priority));
  s.step();
  return sqlite3_changes(db_) > 0;
}

void SqliteJobStore::set_warnings(const std::string& id, const std::string& warnings_json) {
  std::lock_guard lock(mutex_);
  Statement s(*this, "UPDATE jobs SET warnings = ?2 WHERE id = ?1");
  s.bind(1, id);
  s.bind(2, warnings_json);
  s.step();
}

std::optional<int> SqliteJobStore::queue_position(const std::string& id) {
  std::lock_guard lock(mutex_);
  Statement s(*this,
              "SELECT 1 + (SELECT COUNT(*) FROM jobs o WHERE o.state = 'queued' AND "
              "(o.priority > j.priority OR (o.priority = j.priority AND o.seq < j.seq))) "
              "FROM jobs j WHERE j.id = ?1 AND j.state = 'queued'");
  s.bind(1, id);
  if (!s.step()) return std::nullopt;
  return static_cast<int>(s.int64(0));
}

std::optional<JobRecord> SqliteJobStore::find_by_idempotency_key(const std::string& owner, const std::string& key) {
  std::lock_guard lock(mutex_);
  Statement s(*this, std::string("SELECT ") + kJobColumns + " FROM jobs WHERE owner = ?1 AND idempotency_key = ?2");
  s.bind(1, owner);
  s.bind(2, key);
  if (!s.step()) return std::nullopt;
  return s.record(false);
}

std::map<JobState, int> SqliteJobStore::count_by_state(const std::optional<std::string>& owner) {
  std::lock_guard lock(mutex_);
  Statement s(*this,
              std::string("SELECT state, COUNT(*) FROM jobs") + (owner ? " WHERE owner = ?1" : "") + " GROUP BY state");
  if (owner) s.bind(1, *owner);
  std::map<JobState, int> out;
  for (JobState st : kAllJobStates) out[st] = 0;
  while (s.step())
    if (auto st = parse_job_state(s.text(0))) out[*st] = static_cast<int>(s.int64(1));
  return out;
}

std::optional<JobRecord> SqliteJobStore::get(const std::string& id, bool with_document) {
  std::lock_guard lock(mutex_);
  Statement s(*this,
              std::string("SELECT ") + kJobColumns + (with_document ? ", document" : "") + " FROM jobs WHERE id = ?1");
  s.bind(1, id);
  if (!s.step()) return std::nullopt;
  return s.record(with_document);
}

std::vector<JobRecord> SqliteJobStore::list(const JobFilter& filter) {
  std::lock_guard lock(mutex_);
  std::vector<JobState> states = filter.states;
  if (filter.state) states.push_back(*filter.state);
  std::string where;
  auto add = [&](const std::string& cond) { where += (where.empty() ? " WHERE " : " AND ") + cond; };
  if (!states.empty()) add("state IN (" + sql_state_list(states) + ")");
  if (filter.owner) add("owner = ?2");
  if (filter.before_seq) add("seq < ?3");
  if (filter.finished_before_ms) add("finished_at < ?4");
  Statement s(*this, std::string("SELECT ") + kJobColumns + " FROM jobs" + where + " ORDER BY seq DESC LIMIT ?1");
  s.bind(1, static_cast<int64_t>(filter.limit));
  if (filter.owner) s.bind(2, *filter.owner);
  if (filter.before_seq) s.bind(3, *filter.before_seq);
  if (filter.finished_before_ms) s.bind(4, *filter.finished_before_ms);
  std::vector<JobRecord> out;
  while (s.step()) out.push_back(s.record(false));
  return out;
}

bool SqliteJobStore::remove(const std::string& id, std::optional<int64_t> only_finished_before_ms) {
  std::lock_guard lock(mutex_);
  std::string sql = "DELETE FROM jobs WHERE id = ?1";
  if (only_finished_before_ms) sql += " AND state IN (" + sql_terminal_states() + ") AND finished_at < ?2";
  Statement s(*this, sql);
  s.bind(1, id);
  if (only_finished_before_ms) s.bind(2, *only_finished_before_ms);
  s.step();
  return sqlite3_changes(db_) > 0;
}

int SqliteJobStore::requeue_running() {
  std::lock_guard lock(mutex_);
  Statement s(*this,
              "UPDATE jobs SET state = 'queued', started_at = NULL, passes = 0, samples_done = 0, elapsed_s = 0, "
              "eta_s = NULL, samples_per_s = 0, lease_expires_at = NULL, node = '', lost_runs = lost_runs + 1 "
              "WHERE state = 'running'");
  s.step();
  return sqlite3_changes(db_);
}

}  // namespace tessera::server
