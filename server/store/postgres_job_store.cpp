#include "server/store/postgres_job_store.h"

#include <algorithm>
#include <cstdlib>

#include "server/store/job_store_sql.h"
#include "server/store/work_units.h"

namespace tessera::server {

namespace {

// pg_advisory_lock's key for the migrations: "tessera\0" in ASCII, a number no other program is likely to pick.
constexpr const char* kMigrationLock = "8387236830409277696";

// Version 1: the jobs table of SqliteJobStore's version 3, with the node that claimed a running job.
constexpr const char* kMigration1 = R"sql(
  CREATE TABLE tessera_jobs (
    seq BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,  -- submission order: first come, first served
    id TEXT NOT NULL UNIQUE,
    kind TEXT NOT NULL,
    state TEXT NOT NULL CHECK (state IN ('queued','running','paused','succeeded','failed','cancelled')),
    priority INTEGER NOT NULL DEFAULT 0,
    created_at BIGINT NOT NULL,
    started_at BIGINT,
    finished_at BIGINT,
    document TEXT NOT NULL,
    settings TEXT NOT NULL,
    outputs TEXT NOT NULL,
    passes BIGINT NOT NULL DEFAULT 0,
    samples_done BIGINT NOT NULL DEFAULT 0,
    samples_total BIGINT NOT NULL DEFAULT 0,
    elapsed_s DOUBLE PRECISION NOT NULL DEFAULT 0,
    eta_s DOUBLE PRECISION,
    samples_per_s DOUBLE PRECISION NOT NULL DEFAULT 0,
    stop_reason TEXT,
    error TEXT,
    owner TEXT NOT NULL DEFAULT '',
    warnings TEXT NOT NULL DEFAULT '[]',
    idempotency_key TEXT,
    request_hash TEXT,
    name TEXT NOT NULL DEFAULT '',
    node TEXT  -- the daemon rendering it, while it runs
  );
  CREATE INDEX tessera_jobs_queue ON tessera_jobs (state, priority DESC, seq);
  CREATE INDEX tessera_jobs_owner ON tessera_jobs (owner, seq);
  CREATE UNIQUE INDEX tessera_jobs_idempotency ON tessera_jobs (owner, idempotency_key)
    WHERE idempotency_key IS NOT NULL;
)sql";

// Version 2: the lease of a run (JobRecord::epoch).
constexpr const char* kMigration2 = R"sql(
  ALTER TABLE tessera_jobs ADD COLUMN epoch BIGINT NOT NULL DEFAULT 0;
  ALTER TABLE tessera_jobs ADD COLUMN lease_expires_at BIGINT;
)sql";

// Version 3: what crosses nodes as it happens (PostgreSQL's LISTEN/NOTIFY; postgres_notifications.h).
// A job added, deleted, or changed in its state, priority or epoch (a claim) is notified on tessera_jobs as
// "ID STATE" ("ID deleted"), when its transaction commits: a node rendering it learns of a cancel, pause or delete
// made elsewhere at once rather than at its next lease renewal, and an idle node of a job queued elsewhere.
// The events clients stream (Server-Sent Events) are rows of tessera_events: `id` numbers every event (the global
// stream), `job_seq` the events of one job (its stream), both counted in tessera_event_streams, whose global row
// tessera_publish_event() locks until it commits, so that ids become visible in the order they are given (a reader
// that has seen id N never sees a smaller one appear later). Each event is notified on tessera_events as "ID JOB":
// the payload stays small, readers fetch the rows. Kept: the newest p_per_job events of each job and p_total overall.
constexpr const char* kMigration3 = R"sql(
  CREATE FUNCTION tessera_job_changed() RETURNS trigger LANGUAGE plpgsql AS $$
  BEGIN
    IF TG_OP = 'DELETE' THEN
      PERFORM pg_notify('tessera_jobs', OLD.id || ' deleted');
      RETURN OLD;
    END IF;
    PERFORM pg_notify('tessera_jobs', NEW.id || ' ' || NEW.state);
    RETURN NEW;
  END $$;
  CREATE TRIGGER tessera_jobs_added_or_deleted AFTER INSERT OR DELETE ON tessera_jobs
    FOR EACH ROW EXECUTE FUNCTION tessera_job_changed();
  CREATE TRIGGER tessera_jobs_changed AFTER UPDATE ON tessera_jobs FOR EACH ROW
    WHEN (OLD.state IS DISTINCT FROM NEW.state OR OLD.priority IS DISTINCT FROM NEW.priority
          OR OLD.epoch IS DISTINCT FROM NEW.epoch)
    EXECUTE FUNCTION tessera_job_changed();

  CREATE TABLE tessera_events (
    id BIGINT PRIMARY KEY,    -- in the global stream
    job_id TEXT NOT NULL,
    job_seq BIGINT NOT NULL,  -- in the job's stream
    owner TEXT NOT NULL,
    type TEXT NOT NULL,
    data TEXT NOT NULL,
    terminal BOOLEAN NOT NULL
  );
  CREATE UNIQUE INDEX tessera_events_job ON tessera_events (job_id, job_seq);
  CREATE TABLE tessera_event_streams (
    job_id TEXT PRIMARY KEY,  -- '' is the global stream
    last_seq BIGINT NOT NULL
  );
  INSERT INTO tessera_event_streams VALUES ('', 0);
  CREATE FUNCTION tessera_publish_event(p_job TEXT, p_owner TEXT, p_type TEXT, p_data TEXT, p_terminal BOOLEAN,
                                        p_per_job BIGINT, p_total BIGINT) RETURNS BIGINT LANGUAGE plpgsql AS $$
  DECLARE
    g BIGINT;
    s BIGINT;
  BEGIN
    UPDATE tessera_event_streams SET last_seq = last_seq + 1 WHERE job_id = '' RETURNING last_seq INTO g;
    INSERT INTO tessera_event_streams AS t VALUES (p_job, 1)
      ON CONFLICT (job_id) DO UPDATE SET last_seq = t.last_seq + 1 RETURNING last_seq INTO s;
    INSERT INTO tessera_events VALUES (g, p_job, s, p_owner, p_type, p_data, p_terminal);
    DELETE FROM tessera_events WHERE job_id = p_job AND job_seq <= s - p_per_job;
    DELETE FROM tessera_events WHERE id <= g - p_total;
    PERFORM pg_notify('tessera_events', g || ' ' || p_job);
    RETURN g;
  END $$;
)sql";

// Version 4: work units (work_units.h). A split job (units > 1) has one row per sample range and one more, its merge
// (idx = units, no samples), claimable once the others are done. A unit run's epoch comes from its job's epoch
// counter, so (job, epoch) names one run of one unit; checkpoint_epoch names the run whose checkpoint file is the
// unit's (a done unit's: its film).
constexpr const char* kMigration4 = R"sql(
  ALTER TABLE tessera_jobs ADD COLUMN units INTEGER NOT NULL DEFAULT 1;
  CREATE TABLE tessera_units (
    job_id TEXT NOT NULL REFERENCES tessera_jobs (id) ON DELETE CASCADE,
    idx INTEGER NOT NULL,
    first_sample BIGINT NOT NULL,
    samples BIGINT NOT NULL,
    state TEXT NOT NULL DEFAULT 'queued' CHECK (state IN ('queued','running','done')),
    epoch BIGINT NOT NULL DEFAULT 0,
    node TEXT,
    lease_expires_at BIGINT,
    passes BIGINT NOT NULL DEFAULT 0,
    samples_done BIGINT NOT NULL DEFAULT 0,
    elapsed_s DOUBLE PRECISION NOT NULL DEFAULT 0,
    samples_per_s DOUBLE PRECISION NOT NULL DEFAULT 0,
    checkpoint_epoch BIGINT NOT NULL DEFAULT 0,
    finished_at BIGINT,
    PRIMARY KEY (job_id, idx)
  );
  CREATE INDEX tessera_units_claim ON tessera_units (state, job_id);
)sql";

// The text PostgreSQL reads back as the same number.
std::string to_text(int64_t v) {
  return pg_text(v);
}
std::string to_text(double v) {
  return pg_text(v);
}

// Appends a parameter; its placeholder ($N).
std::string placeholder(std::vector<std::optional<std::string>>& params, std::string value) {
  params.push_back(std::move(value));
  std::string out = "$";
  out += std::to_string(params.size());
  return out;
}

std::optional<std::string> text_or_null(const std::string& v) {
  return v.empty() ? std::nullopt : std::optional<std::string>(v);
}

}  // namespace

// A result of one statement, whose rows read as job records (read_job_record()).
class PostgresJobStore::Result : public PgResult {
 public:
  explicit Result(PgResult&& r) : PgResult(std::move(r)) {}
  Result& at(int row) {
    PgResult::at(row);
    return *this;
  }
  JobRecord record(bool with_document) const { return read_job_record(*this, with_document); }
};

PostgresJobStore::PostgresJobStore(const std::string& conninfo, std::string node, int64_t idle_transaction_limit_ms)
    : node_(std::move(node)), conn_(conninfo, "tesserad " + node_, idle_transaction_limit_ms) {
  std::lock_guard lock(mutex_);
  conn_.connect();
  migrate();
}

PostgresJobStore::~PostgresJobStore() = default;

// Version 5: the runs of a job that were lost (JobRecord::lost_runs).
constexpr const char* kMigration5 = R"sql(
  ALTER TABLE tessera_jobs ADD COLUMN lost_runs INTEGER NOT NULL DEFAULT 0;
)sql";

// Version 6: when a unit's lease was last renewed (its node's clock), so that a unit whose node stopped renewing
// shows as stalled before its lease runs out (UnitRecord::renewed_at_ms).
constexpr const char* kMigration6 = R"sql(
  ALTER TABLE tessera_units ADD COLUMN renewed_at BIGINT;
)sql";

// Version 7: the lost runs of each unit (JobRecord::unit_lost_runs): a frame of a range is retried on its own count.
constexpr const char* kMigration7 = R"sql(
  ALTER TABLE tessera_units ADD COLUMN lost_runs INTEGER NOT NULL DEFAULT 0;
)sql";

const std::vector<const char*>& PostgresJobStore::migrations() {
  static const std::vector<const char*> kMigrations = {kMigration1, kMigration2, kMigration3, kMigration4,
                                                       kMigration5, kMigration6, kMigration7};
  return kMigrations;
}

PostgresJobStore::Result PostgresJobStore::exec(const std::string& sql, const Params& params) {
  return Result(conn_.exec(sql, params));
}

void PostgresJobStore::migrate() {
  // One daemon at a time: the others wait here, then find the schema up to date.
  exec(std::string("SELECT pg_advisory_lock(") + kMigrationLock + ")");
  try {
    exec("CREATE TABLE IF NOT EXISTS tessera_schema_version (version INTEGER NOT NULL)");
    Result r = exec("SELECT COALESCE(MAX(version), 0) FROM tessera_schema_version");
    const int version = static_cast<int>(r.int64(0));
    if (version > schema_version())
      throw JobStoreError("job store: the database has schema version " + std::to_string(version) +
                              ", newer than this daemon's " + std::to_string(schema_version()),
                          false);
    for (int v = version + 1; v <= schema_version(); ++v) {
      exec("BEGIN");
      try {
        exec(migrations()[v - 1]);
        exec("INSERT INTO tessera_schema_version (version) VALUES (" + std::to_string(v) + ")");
        exec("COMMIT");
      } catch (...) {
        conn_.exec_quietly("ROLLBACK");
        throw;
      }
    }
  } catch (...) {
    conn_.exec_quietly(std::string("SELECT pg_advisory_unlock(") + kMigrationLock + ")");
    throw;
  }
  exec(std::string("SELECT pg_advisory_unlock(") + kMigrationLock + ")");
}

template <typename F>
auto PostgresJobStore::in_transaction(F&& body) {
  exec("BEGIN");
  try {
    auto out = body();
    exec("COMMIT");
    return out;
  } catch (...) {
    conn_.exec_quietly("ROLLBACK");
    throw;
  }
}

void PostgresJobStore::create(const JobRecord& job) {
  std::lock_guard lock(mutex_);
  const int units = std::max(job.units, 1);
  in_transaction([&] {
    exec(
        "INSERT INTO tessera_jobs (id, kind, state, priority, created_at, document, settings, outputs, "
        "samples_total, owner, warnings, idempotency_key, request_hash, name, units) "
        "VALUES ($1, $2, 'queued', $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14)",
        {job.id, job.kind, to_text(static_cast<int64_t>(job.priority)), to_text(job.created_at_ms), job.document,
         job.settings, job.outputs, to_text(static_cast<int64_t>(job.progress.samples_total)), job.owner,
         job.warnings.empty() ? std::string("[]") : job.warnings, text_or_null(job.idempotency_key),
         text_or_null(job.request_hash), job.name, to_text(static_cast<int64_t>(units))});
    if (units > 1) {
      // The sample ranges, then the merge; numbers this store computed, the id a parameter.
      std::string values;
      int idx = 0;
      for (const SampleRange& r : unit_sample_ranges(job.settings, job.progress.samples_total, units))
        values += "($1," + std::to_string(idx++) + "," + std::to_string(r.first) + "," + std::to_string(r.count) + "),";
      values += "($1," + std::to_string(units) + ",0,0)";
      exec("INSERT INTO tessera_units (job_id, idx, first_sample, samples) VALUES " + values, {job.id});
    }
    return 0;
  });
}

namespace {

// How many runs of the owner `owner_sql` names hold a live lease at $1 (job_store_sql.h).
std::string live_runs_of(const std::string& owner_sql) {
  return sql_live_runs_of("tessera_jobs", "tessera_units", owner_sql, "$1");
}

// pg_advisory_xact_lock's first key for an owner's claims (the second is the hash of the owner): "tess" in ASCII. The
// two-key locks are apart from the one-key lock of the migrations.
constexpr const char* kOwnerClaimLock = "1952805747";

}  // namespace

std::optional<JobRecord> PostgresJobStore::claim_next(int64_t now_ms, int64_t lease_ms, int max_running_per_owner) {
  std::lock_guard lock(mutex_);
  const std::string now = to_text(now_ms), lease = to_text(lease_ms),
                    cap = to_text(static_cast<int64_t>(max_running_per_owner));
  // An owner at the cap is passed over. Two nodes may both see an owner one below it and claim for them at once: the
  // claim then takes the owner's advisory lock (held to the transaction's end), so that claims for one owner take
  // turns, and counts again, seeing the other's committed claim; a claim that finds the owner at the cap after all
  // takes nothing and is tried again, which now passes the owner over.
  for (int attempt = 0;; ++attempt) {
    bool owner_full = false;
    std::optional<JobRecord> claimed = in_transaction([&]() -> std::optional<JobRecord> {
      // A job rendered whole, and a unit of a split job: each the first by priority, then age, that no other node
      // holds; rows other daemons are claiming skipped, not waited for; the better of the two (priority, then first
      // come) is taken and the other's lock released with the transaction. A unit: queued, or running under a lease
      // that expired; the merge only once every range is done.
      Result whole = exec(
          "SELECT seq, priority, owner, state, COALESCE(node, '') FROM tessera_jobs j WHERE units = 1 AND (state = "
          "'queued' OR (state = "
          "'running' AND lease_expires_at < $1)) AND ($2::int <= 0 OR " +
              live_runs_of("j.owner") + " < $2::int) ORDER BY priority DESC, seq LIMIT 1 FOR UPDATE SKIP LOCKED",
          {now, cap});
      Result unit = exec(
          "SELECT u.job_id, u.idx, j.seq, j.priority, j.owner, u.state, COALESCE(u.node, '') FROM tessera_units u "
          "JOIN tessera_jobs j ON "
          "j.id = "
          "u.job_id WHERE j.state IN ('queued', 'running') AND (u.state = 'queued' OR (u.state = 'running' AND "
          "u.lease_expires_at < $1)) AND (u.idx < j.units OR NOT EXISTS (SELECT 1 FROM tessera_units d WHERE "
          "d.job_id = u.job_id AND d.idx < j.units AND d.state <> 'done')) AND ($2::int <= 0 OR " +
              live_runs_of("j.owner") +
              " < $2::int) ORDER BY j.priority DESC, j.seq, u.idx LIMIT 1 FOR UPDATE OF u "
              "SKIP LOCKED",
          {now, cap});
      bool take_unit = unit.rows() > 0;
      if (take_unit && whole.rows() > 0) {
        const int64_t wp = whole.int64(1), up = unit.int64(3);
        take_unit = up > wp || (up == wp && unit.int64(2) < whole.int64(0));
      }
      if (!take_unit && whole.rows() == 0) return std::nullopt;
      if (max_running_per_owner > 0) {
        const std::string owner = take_unit ? unit.text(4) : whole.text(2);
        exec(std::string("SELECT pg_advisory_xact_lock(") + kOwnerClaimLock + ", hashtext($1))", {owner});
        Result runs = exec("SELECT " + live_runs_of("$2"), {now, owner});
        if (runs.int64(0) >= max_running_per_owner) {
          owner_full = true;
          return std::nullopt;
        }
      }
      if (!take_unit) {
        Result r = exec(std::string("UPDATE tessera_jobs SET state = 'running', started_at = $1, node = $2, passes = "
                                    "0, samples_done = 0, elapsed_s = 0, eta_s = NULL, samples_per_s = 0, "
                                    "epoch = epoch + 1, lease_expires_at = $1::bigint + $3::bigint, lost_runs = "
                                    "lost_runs + CASE WHEN state = 'running' THEN 1 ELSE 0 END WHERE seq = $4 "
                                    "RETURNING ") +
                            kJobColumns + ", document",
                        {now, node_, lease, whole.text(0)});
        JobRecord record = r.record(true);
        if (whole.text(3) == "running") record.taken_over_from = whole.text(4);
        return record;
      }
      const std::string job_id = unit.text(0), idx = unit.text(1);
      // The job's epoch counter hands out the unit run's fencing token; the job runs from its first unit's claim.
      // A unit taken over from a run whose lease expired is a lost run of its job.
      const std::string lost = unit.text(5) == "running" ? "1" : "0";
      Result j = exec(std::string("UPDATE tessera_jobs SET epoch = epoch + 1, state = 'running', "
                                  "started_at = COALESCE(started_at, $2), lost_runs = lost_runs + $3::int WHERE id = "
                                  "$1 RETURNING ") +
                          kJobColumns + ", document",
                      {job_id, now, lost});
      JobRecord record = j.record(true);
      Result u = exec(
          "UPDATE tessera_units SET state = 'running', epoch = $3, node = $4, renewed_at = $5::bigint, "
          "lease_expires_at = $5::bigint + $6::bigint, lost_runs = lost_runs + $7::int WHERE job_id = $1 AND idx = $2 "
          "RETURNING first_sample, samples, checkpoint_epoch, (SELECT units FROM tessera_jobs WHERE id = $1), "
          "lost_runs",
          {job_id, idx, to_text(record.epoch), node_, now, lease, lost});
      record.unit = static_cast<int>(std::strtol(idx.c_str(), nullptr, 10));
      record.unit_first_sample = static_cast<uint32_t>(u.int64(0));
      record.unit_samples = static_cast<uint32_t>(u.int64(1));
      record.unit_checkpoint_epoch = u.int64(2);
      record.units = static_cast<int>(u.int64(3));
      record.unit_lost_runs = static_cast<int>(u.int64(4));
      record.node = node_;
      if (unit.text(5) == "running") record.taken_over_from = unit.text(6);
      return record;
    });
    if (claimed || !owner_full || attempt == 2) return claimed;
  }
}

bool PostgresJobStore::renew_lease(const std::string& id, int64_t epoch, int64_t now_ms, int64_t lease_ms) {
  std::lock_guard lock(mutex_);
  // A unit run of a running job, or a job rendered whole: (id, epoch) names one of them at most.
  return exec(
             "WITH u AS (UPDATE tessera_units u SET renewed_at = $3::bigint, lease_expires_at = $3::bigint + "
             "$4::bigint "
             "FROM tessera_jobs j "
             "WHERE u.job_id = $1 AND u.epoch = $2 AND u.state = 'running' AND j.id = u.job_id AND "
             "j.state = 'running' RETURNING 1), w AS (UPDATE tessera_jobs SET lease_expires_at = $3::bigint + "
             "$4::bigint WHERE id = $1 AND state = 'running' AND epoch = $2 AND units = 1 RETURNING 1) "
             "SELECT (SELECT COUNT(*) FROM u) + (SELECT COUNT(*) FROM w)",
             {id, to_text(epoch), to_text(now_ms), to_text(lease_ms)})
             .int64(0) > 0;
}

bool PostgresJobStore::update_progress(const std::string& id, int64_t epoch, const JobProgress& p) {
  std::lock_guard lock(mutex_);
  const Params params{id,
                      to_text(static_cast<int64_t>(p.passes)),
                      to_text(static_cast<int64_t>(p.samples_done)),
                      to_text(static_cast<int64_t>(p.samples_total)),
                      to_text(p.elapsed_s),
                      p.eta_s ? std::optional<std::string>(to_text(*p.eta_s)) : std::nullopt,
                      to_text(p.samples_per_s),
                      to_text(epoch)};
  // A unit run: its own row (the checkpoint it just wrote becomes the unit's), then the job's progress over all its
  // units and nodes.
  if (exec("UPDATE tessera_units u SET passes = $2, samples_done = $3, elapsed_s = $4, samples_per_s = $5, "
           "checkpoint_epoch = $6 FROM tessera_jobs j WHERE u.job_id = $1 AND u.epoch = $6 AND u.state = 'running' "
           "AND j.id = u.job_id AND j.state = 'running'",
           {id, params[1], params[2], params[4], params[6], params[7]})
          .affected() > 0) {
    aggregate_units(id);
    return true;
  }
  return exec(
             "UPDATE tessera_jobs SET passes = $2, samples_done = $3, samples_total = $4, elapsed_s = $5, "
             "eta_s = $6, samples_per_s = $7 WHERE id = $1 AND state = 'running' AND epoch = $8 AND units = 1",
             params)
             .affected() > 0;
}

// The progress of a split job over all its units: samples and passes done, render time summed over nodes, the rate
// of the units rendering now, and the time left at that rate.
void PostgresJobStore::aggregate_units(const std::string& id) {
  exec(
      "UPDATE tessera_jobs j SET passes = a.passes, samples_done = a.done, elapsed_s = a.elapsed, "
      "samples_per_s = a.rate, eta_s = CASE WHEN a.spp_rate > 0 THEN GREATEST(j.samples_total - a.done, 0) / "
      "a.spp_rate END FROM (SELECT COALESCE(SUM(passes), 0) AS passes, COALESCE(SUM(samples_done), 0) AS done, "
      "COALESCE(SUM(elapsed_s), 0) AS elapsed, COALESCE(SUM(samples_per_s) FILTER (WHERE state = 'running'), 0) "
      "AS rate, COALESCE(SUM(samples_done / elapsed_s) FILTER (WHERE state = 'running' AND elapsed_s > 0), 0) AS "
      "spp_rate FROM tessera_units WHERE job_id = $1) a WHERE j.id = $1 AND j.state = 'running'",
      {id});
}

bool PostgresJobStore::transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                                  const std::string& error, std::optional<JobState> only_from) {
  std::lock_guard lock(mutex_);
  return in_transaction(
      [&] { return move(id, to, now_ms, stop_reason, error, sql_states_into(to, only_from), std::nullopt); });
}

bool PostgresJobStore::end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms,
                               const std::string& stop_reason, const std::string& error) {
  std::lock_guard lock(mutex_);
  return in_transaction([&] {
    // A unit run of this epoch, of a job still running (both rows locked until the end of the move)?
    Result u = exec(
        "SELECT u.idx, j.units FROM tessera_units u JOIN tessera_jobs j ON j.id = u.job_id WHERE u.job_id = $1 AND "
        "u.epoch = $2 AND u.state = 'running' AND j.state = 'running' FOR UPDATE OF u",
        {id, to_text(epoch)});
    if (u.rows() == 0) return move(id, to, now_ms, stop_reason, error, sql_states_into(to, JobState::kRunning), epoch);
    const bool merge = u.int64(0) == u.int64(1);
    const Params unit{id, u.text(0), to_text(now_ms)};
    if (to == JobState::kQueued) {
      // Stopping: the unit waits for the next node, its checkpoint kept.
      exec(
          "UPDATE tessera_units SET state = 'queued', node = NULL, lease_expires_at = NULL WHERE job_id = $1 AND "
          "idx = $2",
          {id, u.text(0)});
      return true;
    }
    if (to == JobState::kSucceeded) {
      // Its film is this run's last checkpoint, written before; the node that rendered it stays named.
      exec(
          "UPDATE tessera_units SET state = 'done', lease_expires_at = NULL, finished_at = $3, "
          "samples_done = samples, checkpoint_epoch = epoch WHERE job_id = $1 AND idx = $2",
          unit);
      if (!merge) {
        aggregate_units(id);
        return true;
      }
    }
    // The merge's success, or a failure, pause or cancel by the node rendering a unit: the job's move.
    return move(id, to, now_ms, stop_reason, error, sql_states_into(to, JobState::kRunning), std::nullopt);
  });
}

bool PostgresJobStore::move(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                            const std::string& error, const std::string& from_states, std::optional<int64_t> epoch) {
  if (from_states.empty()) return false;
  Params params{id};
  std::string where = " WHERE id = $1 AND state IN (" + from_states + ")";
  auto param = [&](std::string value) { return placeholder(params, std::move(value)); };
  // A run's epoch fences a job rendered whole; a unit's run is fenced by its unit row (end_run).
  if (epoch) where += " AND units = 1 AND epoch = " + param(to_text(*epoch));
  // Out of running, the lease ends with the run.
  if (to == JobState::kQueued) {
    // Back to the queue from an end (a requeue): its units start over too. From paused (a resume) they are kept.
    exec(
        "UPDATE tessera_units SET state = 'queued', node = NULL, lease_expires_at = NULL, passes = 0, "
        "samples_done = 0, elapsed_s = 0, samples_per_s = 0, checkpoint_epoch = 0, finished_at = NULL, lost_runs = 0 "
        "WHERE job_id = $1 AND (SELECT state FROM tessera_jobs WHERE id = $1) IN (" +
            sql_terminal_states() + ") AND (SELECT state FROM tessera_jobs WHERE id = $1) IN (" + from_states + ")",
        {id});
    return exec(
               "UPDATE tessera_jobs SET state = 'queued', node = NULL, lease_expires_at = NULL, started_at = NULL, "
               "finished_at = NULL, stop_reason = NULL, error = NULL, passes = 0, samples_done = 0, elapsed_s = 0, "
               "eta_s = NULL, samples_per_s = 0, lost_runs = CASE WHEN state IN (" +
                   sql_terminal_states() + ") THEN 0 ELSE lost_runs END" + where,
               params)
               .affected() > 0;
  }
  if (to == JobState::kRunning) {
    const std::string started = param(to_text(now_ms));
    return exec("UPDATE tessera_jobs SET state = 'running', node = " + param(node_) + ", started_at = " + started +
                    where,
                params)
               .affected() > 0;
  }
  if (to == JobState::kPaused) {
    // Units before the job, in the order a claim locks them (a unit, then its job): no deadlock.
    exec("SELECT 1 FROM tessera_units WHERE job_id = $1 FOR UPDATE", {id});
    const bool moved =
        exec("UPDATE tessera_jobs SET state = 'paused', node = NULL, lease_expires_at = NULL, eta_s = NULL" + where,
             params)
            .affected() > 0;
    // Its units' runs end with it (their renewals now fail): each waits, with its checkpoint, for the resume.
    if (moved)
      exec(
          "UPDATE tessera_units SET state = 'queued', node = NULL, lease_expires_at = NULL WHERE job_id = $1 AND "
          "state = 'running'",
          {id});
    return moved;
  }
  const std::string finished = param(to_text(now_ms));
  const std::string state = param(job_state_name(to));
  const std::string reason = param(stop_reason);
  const std::string why = param(error);
  return exec("UPDATE tessera_jobs SET state = " + state + ", node = NULL, lease_expires_at = NULL, finished_at = " +
                  finished + ", stop_reason = NULLIF(" + reason + ", ''), error = NULLIF(" + why +
                  ", ''), eta_s = CASE WHEN " + state + " = 'succeeded' THEN 0 ELSE eta_s END" + where,
              params)
             .affected() > 0;
}

bool PostgresJobStore::set_priority(const std::string& id, int priority) {
  std::lock_guard lock(mutex_);
  return exec("UPDATE tessera_jobs SET priority = $2 WHERE id = $1 AND state IN (" +
                  sql_state_list(action_states(JobAction::kPriority)) + ")",
              {id, to_text(static_cast<int64_t>(priority))})
             .affected() > 0;
}

void PostgresJobStore::set_warnings(const std::string& id, const std::string& warnings_json) {
  std::lock_guard lock(mutex_);
  exec("UPDATE tessera_jobs SET warnings = $2 WHERE id = $1", {id, warnings_json});
}

std::optional<int> PostgresJobStore::queue_position(const std::string& id) {
  std::lock_guard lock(mutex_);
  Result r = exec(
      "SELECT 1 + (SELECT COUNT(*) FROM tessera_jobs o WHERE o.state = 'queued' AND "
      "(o.priority > j.priority OR (o.priority = j.priority AND o.seq < j.seq))) "
      "FROM tessera_jobs j WHERE j.id = $1 AND j.state = 'queued'",
      {id});
  if (r.rows() == 0) return std::nullopt;
  return static_cast<int>(r.int64(0));
}

std::optional<JobRecord> PostgresJobStore::find_by_idempotency_key(const std::string& owner, const std::string& key) {
  std::lock_guard lock(mutex_);
  Result r = exec(std::string("SELECT ") + kJobColumns + " FROM tessera_jobs WHERE owner = $1 AND idempotency_key = $2",
                  {owner, key});
  if (r.rows() == 0) return std::nullopt;
  return r.record(false);
}

std::map<JobState, int> PostgresJobStore::count_by_state(const std::optional<std::string>& owner) {
  std::lock_guard lock(mutex_);
  Result r = owner ? exec("SELECT state, COUNT(*) FROM tessera_jobs WHERE owner = $1 GROUP BY state", {*owner})
                   : exec("SELECT state, COUNT(*) FROM tessera_jobs GROUP BY state");
  std::map<JobState, int> out;
  for (JobState st : kAllJobStates) out[st] = 0;
  for (int i = 0; i < r.rows(); ++i)
    if (auto st = parse_job_state(r.at(i).text(0))) out[*st] = static_cast<int>(r.int64(1));
  return out;
}

std::optional<JobRecord> PostgresJobStore::get(const std::string& id, bool with_document) {
  std::lock_guard lock(mutex_);
  Result r = exec(
      std::string("SELECT ") + kJobColumns + (with_document ? ", document" : "") + " FROM tessera_jobs WHERE id = $1",
      {id});
  if (r.rows() == 0) return std::nullopt;
  return r.record(with_document);
}

std::vector<JobRecord> PostgresJobStore::list(const JobFilter& filter) {
  std::vector<JobState> states = filter.states;
  if (filter.state) states.push_back(*filter.state);
  std::string where;
  Params params{to_text(static_cast<int64_t>(filter.limit))};
  auto add = [&](const std::string& cond) { where += (where.empty() ? " WHERE " : " AND ") + cond; };
  auto param = [&](std::string value) { return placeholder(params, std::move(value)); };
  if (!states.empty()) add("state IN (" + sql_state_list(states) + ")");
  if (filter.owner) add("owner = " + param(*filter.owner));
  if (filter.before_seq) add("seq < " + param(to_text(*filter.before_seq)));
  if (filter.finished_before_ms) add("finished_at < " + param(to_text(*filter.finished_before_ms)));
  std::lock_guard lock(mutex_);
  Result r =
      exec(std::string("SELECT ") + kJobColumns + " FROM tessera_jobs" + where + " ORDER BY seq DESC LIMIT $1", params);
  std::vector<JobRecord> out;
  for (int i = 0; i < r.rows(); ++i) out.push_back(r.at(i).record(false));
  return out;
}

bool PostgresJobStore::remove(const std::string& id, std::optional<int64_t> only_finished_before_ms) {
  std::lock_guard lock(mutex_);
  return in_transaction([&] {
    // A split job's units first, as a claim locks them (a unit, then its job), then the job and, by cascade, its
    // units: no deadlock with a node claiming one of them.
    exec("SELECT 1 FROM tessera_units WHERE job_id = $1 FOR UPDATE", {id});
    if (only_finished_before_ms)
      return exec("DELETE FROM tessera_jobs WHERE id = $1 AND state IN (" + sql_terminal_states() +
                      ") AND finished_at < $2",
                  {id, to_text(*only_finished_before_ms)})
                 .affected() > 0;
    return exec("DELETE FROM tessera_jobs WHERE id = $1", {id}).affected() > 0;
  });
}

std::vector<UnitRecord> PostgresJobStore::units(const std::string& id) {
  std::lock_guard lock(mutex_);
  Result r = exec(std::string("SELECT ") + kUnitColumns +
                      " FROM tessera_units u JOIN tessera_jobs j ON j.id = u.job_id WHERE u.job_id = $1 AND u.idx < "
                      "j.units ORDER BY u.idx",
                  {id});
  std::vector<UnitRecord> out;
  for (int i = 0; i < r.rows(); ++i) out.push_back(read_unit_record(r.at(i)));
  return out;
}

int PostgresJobStore::requeue_running() {
  std::lock_guard lock(mutex_);
  // The units this node was rendering wait for any node, with their checkpoints; each job of them lost a run.
  exec(
      "UPDATE tessera_jobs SET lost_runs = lost_runs + 1 WHERE id IN (SELECT job_id FROM tessera_units WHERE state = "
      "'running' AND node = $1)",
      {node_});
  const int units = exec(
                        "UPDATE tessera_units SET state = 'queued', node = NULL, lease_expires_at = NULL, "
                        "lost_runs = lost_runs + 1 WHERE state = 'running' AND node = $1",
                        {node_})
                        .affected();
  return units +
         exec(
             "UPDATE tessera_jobs SET state = 'queued', node = NULL, lease_expires_at = NULL, started_at = NULL, "
             "passes = 0, samples_done = 0, elapsed_s = 0, eta_s = NULL, samples_per_s = 0, lost_runs = lost_runs + 1 "
             "WHERE state = 'running' AND node = $1",
             {node_})
             .affected();
}

}  // namespace tessera::server
