#include "server/store/sqlite_job_store.h"

#include <sqlite3.h>

#include <cerrno>

#include "server/base/file_io.h"
#include "server/store/job_store_sql.h"
#include "server/store/work_units.h"

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
    if (version < 6) {
      // Version 6: work units (work_units.h), as PostgresJobStore's tessera_units: a job of units > 1 has one row
      // per unit and one more, its end (idx = units, no samples), claimable once the others are done. A unit run's
      // epoch comes from its job's epoch counter.
      exec("ALTER TABLE jobs ADD COLUMN units INTEGER NOT NULL DEFAULT 1");
      exec(R"sql(
        CREATE TABLE units (
          job_id TEXT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
          idx INTEGER NOT NULL,
          first_sample INTEGER NOT NULL,
          samples INTEGER NOT NULL,
          state TEXT NOT NULL DEFAULT 'queued' CHECK (state IN ('queued','running','done')),
          epoch INTEGER NOT NULL DEFAULT 0,
          node TEXT,
          lease_expires_at INTEGER,
          renewed_at INTEGER,
          passes INTEGER NOT NULL DEFAULT 0,
          samples_done INTEGER NOT NULL DEFAULT 0,
          elapsed_s REAL NOT NULL DEFAULT 0,
          samples_per_s REAL NOT NULL DEFAULT 0,
          checkpoint_epoch INTEGER NOT NULL DEFAULT 0,
          finished_at INTEGER,
          lost_runs INTEGER NOT NULL DEFAULT 0,
          PRIMARY KEY (job_id, idx)
        ))sql");
      exec("CREATE INDEX units_claim ON units (state, job_id)");
      exec("INSERT INTO schema_version (version) VALUES (6)");
    }
    exec("COMMIT");
  } catch (...) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    throw;
  }
}

template <typename F>
auto SqliteJobStore::in_transaction(F&& body) {
  exec("BEGIN IMMEDIATE");
  try {
    auto out = body();
    exec("COMMIT");
    return out;
  } catch (...) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    throw;
  }
}

void SqliteJobStore::create(const JobRecord& job) {
  std::lock_guard lock(mutex_);
  const int units = std::max(job.units, 1);
  in_transaction([&] {
    {
      Statement s(
          *this,
          "INSERT INTO jobs (id, kind, state, priority, created_at, document, settings, outputs, samples_total, "
          "owner, warnings, idempotency_key, request_hash, name, units) "
          "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15)");
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
      s.bind(15, static_cast<int64_t>(units));
      s.step();
    }
    if (units > 1) {
      // Its units, then the end (idx = units, no samples).
      const std::vector<SampleRange> ranges = unit_sample_ranges(job.settings, job.progress.samples_total, units);
      for (int idx = 0; idx <= units; ++idx) {
        Statement u(*this, "INSERT INTO units (job_id, idx, first_sample, samples) VALUES (?1, ?2, ?3, ?4)");
        u.bind(1, job.id);
        u.bind(2, static_cast<int64_t>(idx));
        u.bind(3, static_cast<int64_t>(idx < units ? ranges[static_cast<size_t>(idx)].first : 0));
        u.bind(4, static_cast<int64_t>(idx < units ? ranges[static_cast<size_t>(idx)].count : 0));
        u.step();
      }
    }
    return 0;
  });
}

namespace {

// How many runs of the owner `owner_sql` names hold a live lease at ?1 (job_store_sql.h).
std::string live_runs_of(const std::string& owner_sql) {
  return sql_live_runs_of("jobs", "units", owner_sql, "?1");
}

}  // namespace

std::optional<JobRecord> SqliteJobStore::claim_next(int64_t now_ms, int64_t lease_ms, int max_running_per_owner) {
  std::lock_guard lock(mutex_);
  // One write transaction, so two daemons sharing the file can never claim the same job or unit, nor an owner's runs
  // pass the cap (the write lock serialises them). As PostgresJobStore: the first job rendered whole and the first
  // unit, each by priority then age, queued or running under a lease that expired (a unit's end only once the others
  // are done), and the better of the two taken.
  return in_transaction([&]() -> std::optional<JobRecord> {
    std::optional<int64_t> whole_seq, whole_priority;
    {
      Statement w(*this,
                  "SELECT seq, priority FROM jobs c WHERE c.units = 1 AND (c.state = 'queued' OR (c.state = "
                  "'running' AND c.lease_expires_at < ?1)) AND (?2 <= 0 OR " +
                      live_runs_of("c.owner") + " < ?2) ORDER BY c.priority DESC, c.seq LIMIT 1");
      w.bind(1, now_ms);
      w.bind(2, static_cast<int64_t>(max_running_per_owner));
      if (w.step()) {
        whole_seq = w.int64(0);
        whole_priority = w.int64(1);
      }
    }
    std::string unit_job;
    int64_t unit_idx = 0, unit_seq = 0, unit_priority = 0;
    bool unit_lost = false, have_unit = false;
    {
      Statement u(*this,
                  "SELECT u.job_id, u.idx, j.seq, j.priority, u.state FROM units u JOIN jobs j ON j.id = u.job_id "
                  "WHERE j.state IN ('queued', 'running') AND (u.state = 'queued' OR (u.state = 'running' AND "
                  "u.lease_expires_at < ?1)) AND (u.idx < j.units OR NOT EXISTS (SELECT 1 FROM units d WHERE "
                  "d.job_id = u.job_id AND d.idx < j.units AND d.state <> 'done')) AND (?2 <= 0 OR " +
                      live_runs_of("j.owner") + " < ?2) ORDER BY j.priority DESC, j.seq, u.idx LIMIT 1");
      u.bind(1, now_ms);
      u.bind(2, static_cast<int64_t>(max_running_per_owner));
      if (u.step()) {
        have_unit = true;
        unit_job = u.text(0);
        unit_idx = u.int64(1);
        unit_seq = u.int64(2);
        unit_priority = u.int64(3);
        unit_lost = u.text(4) == "running";
      }
    }
    bool take_unit = have_unit;
    if (have_unit && whole_seq)
      take_unit = unit_priority > *whole_priority || (unit_priority == *whole_priority && unit_seq < *whole_seq);
    if (take_unit) return std::optional<JobRecord>(claim_unit(unit_job, unit_idx, unit_lost, now_ms, lease_ms));
    if (!whole_seq) return std::optional<JobRecord>();
    Statement s(*this, std::string("UPDATE jobs SET state = 'running', started_at = ?1, passes = 0, samples_done = 0, "
                                   "elapsed_s = 0, eta_s = NULL, samples_per_s = 0, epoch = epoch + 1, "
                                   "lease_expires_at = ?1 + ?2, lost_runs = lost_runs + (state = 'running') "
                                   "WHERE seq = ?3 RETURNING ") +
                           kJobColumns + ", document");
    s.bind(1, now_ms);
    s.bind(2, lease_ms);
    s.bind(3, *whole_seq);
    if (!s.step()) return std::optional<JobRecord>();
    JobRecord r = s.record(true);
    while (s.step()) {
    }
    return std::optional<JobRecord>(std::move(r));
  });
}

JobRecord SqliteJobStore::claim_unit(const std::string& job_id, int64_t idx, bool lost, int64_t now_ms,
                                     int64_t lease_ms) {
  // The job's epoch counter hands out the unit run's fencing token; the job runs from its first unit's claim. A unit
  // taken over from a run whose lease expired is a lost run of its job, and of the unit.
  JobRecord record;
  {
    Statement j(*this, std::string("UPDATE jobs SET epoch = epoch + 1, state = 'running', started_at = "
                                   "COALESCE(started_at, ?2), lost_runs = lost_runs + ?3 WHERE id = ?1 RETURNING ") +
                           kJobColumns + ", document");
    j.bind(1, job_id);
    j.bind(2, now_ms);
    j.bind(3, static_cast<int64_t>(lost));
    if (!j.step()) throw JobStoreError("job store: the job of a unit claimed is gone", false);
    record = j.record(true);
    while (j.step()) {
    }
  }
  Statement u(*this,
              "UPDATE units SET state = 'running', epoch = ?3, node = '', renewed_at = ?4, lease_expires_at = ?4 + ?5, "
              "lost_runs = lost_runs + ?6 WHERE job_id = ?1 AND idx = ?2 RETURNING first_sample, samples, "
              "checkpoint_epoch, (SELECT units FROM jobs WHERE id = ?1), lost_runs");
  u.bind(1, job_id);
  u.bind(2, idx);
  u.bind(3, record.epoch);
  u.bind(4, now_ms);
  u.bind(5, lease_ms);
  u.bind(6, static_cast<int64_t>(lost));
  if (!u.step()) throw JobStoreError("job store: a unit claimed is gone", false);
  record.unit = static_cast<int>(idx);
  record.unit_first_sample = static_cast<uint32_t>(u.int64(0));
  record.unit_samples = static_cast<uint32_t>(u.int64(1));
  record.unit_checkpoint_epoch = u.int64(2);
  record.units = static_cast<int>(u.int64(3));
  record.unit_lost_runs = static_cast<int>(u.int64(4));
  while (u.step()) {
  }
  return record;
}

bool SqliteJobStore::renew_lease(const std::string& id, int64_t epoch, int64_t now_ms, int64_t lease_ms) {
  std::lock_guard lock(mutex_);
  // A unit run of a running job, or a job rendered whole: (id, epoch) names one of them at most.
  {
    Statement u(*this,
                "UPDATE units SET renewed_at = ?3, lease_expires_at = ?3 + ?4 WHERE job_id = ?1 AND epoch = ?2 AND "
                "state = 'running' AND (SELECT state FROM jobs WHERE id = ?1) = 'running'");
    u.bind(1, id);
    u.bind(2, epoch);
    u.bind(3, now_ms);
    u.bind(4, lease_ms);
    u.step();
    if (sqlite3_changes(db_) > 0) return true;
  }
  Statement s(*this,
              "UPDATE jobs SET lease_expires_at = ?3 + ?4 WHERE id = ?1 AND state = 'running' AND epoch = ?2 AND "
              "units = 1");
  s.bind(1, id);
  s.bind(2, epoch);
  s.bind(3, now_ms);
  s.bind(4, lease_ms);
  s.step();
  return sqlite3_changes(db_) > 0;
}

bool SqliteJobStore::update_progress(const std::string& id, int64_t epoch, const JobProgress& p) {
  std::lock_guard lock(mutex_);
  // A unit run: its own row (the checkpoint it just wrote becomes the unit's), then the job's progress over its units.
  const bool unit = in_transaction([&] {
    Statement u(*this,
                "UPDATE units SET passes = ?2, samples_done = ?3, elapsed_s = ?4, samples_per_s = ?5, "
                "checkpoint_epoch = ?6 WHERE job_id = ?1 AND epoch = ?6 AND state = 'running' AND (SELECT state FROM "
                "jobs WHERE id = ?1) = 'running'");
    u.bind(1, id);
    u.bind(2, static_cast<int64_t>(p.passes));
    u.bind(3, static_cast<int64_t>(p.samples_done));
    u.bind(4, p.elapsed_s);
    u.bind(5, p.samples_per_s);
    u.bind(6, epoch);
    u.step();
    if (sqlite3_changes(db_) == 0) return false;
    aggregate_units(id);
    return true;
  });
  if (unit) return true;
  Statement s(*this,
              "UPDATE jobs SET passes = ?2, samples_done = ?3, samples_total = ?4, elapsed_s = ?5, eta_s = ?6, "
              "samples_per_s = ?7 WHERE id = ?1 AND state = 'running' AND epoch = ?8 AND units = 1");
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

void SqliteJobStore::aggregate_units(const std::string& id) {
  Statement s(
      *this,
      "UPDATE jobs SET passes = a.passes, samples_done = a.done, elapsed_s = a.elapsed, samples_per_s = a.rate, "
      "eta_s = CASE WHEN a.spp_rate > 0 THEN max(jobs.samples_total - a.done, 0) / a.spp_rate END FROM "
      "(SELECT COALESCE(SUM(passes), 0) AS passes, COALESCE(SUM(samples_done), 0) AS done, "
      "COALESCE(SUM(elapsed_s), 0) AS elapsed, COALESCE(SUM(samples_per_s) FILTER (WHERE state = 'running'), "
      "0) AS rate, COALESCE(SUM(samples_done / elapsed_s) FILTER (WHERE state = 'running' AND elapsed_s > 0), "
      "0) AS spp_rate FROM units WHERE job_id = ?1) AS a WHERE jobs.id = ?1 AND jobs.state = 'running'");
  s.bind(1, id);
  s.step();
}

bool SqliteJobStore::transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                                const std::string& error, std::optional<JobState> only_from) {
  std::lock_guard lock(mutex_);
  return move(id, to, now_ms, stop_reason, error, sql_states_into(to, only_from), std::nullopt);
}

bool SqliteJobStore::end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms,
                             const std::string& stop_reason, const std::string& error) {
  std::lock_guard lock(mutex_);
  return in_transaction([&] {
    // A unit run of this epoch, of a job still running?
    int64_t idx = -1, units = 0;
    {
      Statement u(*this,
                  "SELECT u.idx, j.units FROM units u JOIN jobs j ON j.id = u.job_id WHERE u.job_id = ?1 AND "
                  "u.epoch = ?2 AND u.state = 'running' AND j.state = 'running'");
      u.bind(1, id);
      u.bind(2, epoch);
      if (u.step()) {
        idx = u.int64(0);
        units = u.int64(1);
      }
    }
    if (idx < 0) return move(id, to, now_ms, stop_reason, error, sql_states_into(to, JobState::kRunning), epoch);
    if (to == JobState::kQueued) {
      // Stopping: the unit waits for the next claim, its checkpoint kept.
      Statement q(*this,
                  "UPDATE units SET state = 'queued', node = NULL, lease_expires_at = NULL WHERE job_id = ?1 AND "
                  "idx = ?2");
      q.bind(1, id);
      q.bind(2, idx);
      q.step();
      return true;
    }
    if (to == JobState::kSucceeded) {
      Statement d(*this,
                  "UPDATE units SET state = 'done', lease_expires_at = NULL, finished_at = ?3, samples_done = samples, "
                  "checkpoint_epoch = epoch WHERE job_id = ?1 AND idx = ?2");
      d.bind(1, id);
      d.bind(2, idx);
      d.bind(3, now_ms);
      d.step();
      if (idx < units) {
        aggregate_units(id);
        return true;
      }
    }
    // The end unit's success, or a failure, pause or cancel by the run of a unit: the job's move.
    return move(id, to, now_ms, stop_reason, error, sql_states_into(to, JobState::kRunning), std::nullopt);
  });
}

bool SqliteJobStore::move(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                          const std::string& error, const std::string& from_states, std::optional<int64_t> epoch) {
  if (from_states.empty()) return false;
  // Out of running, the lease ends with the run.
  // A run's epoch fences a job rendered whole; a unit's run is fenced by its unit row (end_run).
  const std::string where =
      " WHERE id = ?1 AND state IN (" + from_states + ")" + (epoch ? " AND epoch = ?6 AND units = 1" : "");
  if (to == JobState::kQueued) {
    // Back to the queue from an end (a requeue): its units start over too. From paused (a resume) they are kept.
    Statement u(
        *this,
        "UPDATE units SET state = 'queued', node = NULL, lease_expires_at = NULL, passes = 0, samples_done = 0, "
        "elapsed_s = 0, samples_per_s = 0, checkpoint_epoch = 0, finished_at = NULL, lost_runs = 0 WHERE "
        "job_id = ?1 AND (SELECT state FROM jobs WHERE id = ?1) IN (" +
            sql_terminal_states() + ") AND (SELECT state FROM jobs WHERE id = ?1) IN (" + from_states + ")");
    u.bind(1, id);
    u.step();
  }
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
  const bool moved = sqlite3_changes(db_) > 0;
  if (moved && to == JobState::kPaused) {
    // Its units' runs end with it (their renewals now fail): each waits, with its checkpoint, for the resume.
    Statement u(*this,
                "UPDATE units SET state = 'queued', node = NULL, lease_expires_at = NULL WHERE job_id = ?1 AND "
                "state = 'running'");
    u.bind(1, id);
    u.step();
  }
  return moved;
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
  // The units left running wait for the next claim, each counting a lost run (as their jobs do, below).
  int units = 0;
  {
    Statement u(*this,
                "UPDATE units SET state = 'queued', node = NULL, lease_expires_at = NULL, lost_runs = lost_runs + 1 "
                "WHERE state = 'running'");
    u.step();
    units = sqlite3_changes(db_);
  }
  Statement s(*this,
              "UPDATE jobs SET state = 'queued', started_at = NULL, passes = 0, samples_done = 0, elapsed_s = 0, "
              "eta_s = NULL, samples_per_s = 0, lease_expires_at = NULL, node = '', lost_runs = lost_runs + 1 "
              "WHERE state = 'running'");
  s.step();
  return units + sqlite3_changes(db_);
}

std::vector<UnitRecord> SqliteJobStore::units(const std::string& id) {
  std::lock_guard lock(mutex_);
  Statement s(*this,
              std::string("SELECT ") + kUnitColumns +
                  " FROM units u JOIN jobs j ON j.id = u.job_id WHERE u.job_id = ?1 AND u.idx < j.units ORDER BY "
                  "u.idx");
  s.bind(1, id);
  std::vector<UnitRecord> out;
  while (s.step()) out.push_back(read_unit_record(s));
  return out;
}

}  // namespace tessera::server
