#include "server/postgres_job_store.h"

#include "server/job_store_sql.h"

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

PostgresJobStore::PostgresJobStore(const std::string& conninfo, std::string node)
    : node_(std::move(node)), conn_(conninfo) {
  std::lock_guard lock(mutex_);
  conn_.connect();
  migrate();
}

PostgresJobStore::~PostgresJobStore() = default;

const std::vector<const char*>& PostgresJobStore::migrations() {
  static const std::vector<const char*> kMigrations = {kMigration1, kMigration2, kMigration3};
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

void PostgresJobStore::create(const JobRecord& job) {
  std::lock_guard lock(mutex_);
  exec(
      "INSERT INTO tessera_jobs (id, kind, state, priority, created_at, document, settings, outputs, samples_total, "
      "owner, warnings, idempotency_key, request_hash, name) "
      "VALUES ($1, $2, 'queued', $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13)",
      {job.id, job.kind, to_text(static_cast<int64_t>(job.priority)), to_text(job.created_at_ms), job.document,
       job.settings, job.outputs, to_text(static_cast<int64_t>(job.progress.samples_total)), job.owner,
       job.warnings.empty() ? std::string("[]") : job.warnings, text_or_null(job.idempotency_key),
       text_or_null(job.request_hash), job.name});
}

std::optional<JobRecord> PostgresJobStore::claim_next(int64_t now_ms, int64_t lease_ms) {
  std::lock_guard lock(mutex_);
  // The row is locked as it is chosen; rows other daemons are claiming are skipped, not waited for.
  Result r = exec(std::string("UPDATE tessera_jobs SET state = 'running', started_at = $1, node = $2, passes = 0, "
                              "samples_done = 0, elapsed_s = 0, eta_s = NULL, samples_per_s = 0, epoch = epoch + 1, "
                              "lease_expires_at = $1::bigint + $3::bigint "
                              "WHERE seq = (SELECT seq FROM tessera_jobs WHERE state = 'queued' OR (state = 'running' "
                              "AND lease_expires_at < $1) ORDER BY priority DESC, seq LIMIT 1 FOR UPDATE SKIP LOCKED) "
                              "RETURNING ") +
                      kJobColumns + ", document",
                  {to_text(now_ms), node_, to_text(lease_ms)});
  if (r.rows() == 0) return std::nullopt;
  return r.record(true);
}

bool PostgresJobStore::renew_lease(const std::string& id, int64_t epoch, int64_t now_ms, int64_t lease_ms) {
  std::lock_guard lock(mutex_);
  return exec(
             "UPDATE tessera_jobs SET lease_expires_at = $3::bigint + $4::bigint WHERE id = $1 AND "
             "state = 'running' AND epoch = $2",
             {id, to_text(epoch), to_text(now_ms), to_text(lease_ms)})
             .affected() > 0;
}

bool PostgresJobStore::update_progress(const std::string& id, int64_t epoch, const JobProgress& p) {
  std::lock_guard lock(mutex_);
  return exec(
             "UPDATE tessera_jobs SET passes = $2, samples_done = $3, samples_total = $4, elapsed_s = $5, "
             "eta_s = $6, samples_per_s = $7 WHERE id = $1 AND state = 'running' AND epoch = $8",
             {id, to_text(static_cast<int64_t>(p.passes)), to_text(static_cast<int64_t>(p.samples_done)),
              to_text(static_cast<int64_t>(p.samples_total)), to_text(p.elapsed_s),
              p.eta_s ? std::optional<std::string>(to_text(*p.eta_s)) : std::nullopt, to_text(p.samples_per_s),
              to_text(epoch)})
             .affected() > 0;
}

bool PostgresJobStore::transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                                  const std::string& error, std::optional<JobState> only_from) {
  std::lock_guard lock(mutex_);
  return move(id, to, now_ms, stop_reason, error, sql_states_into(to, only_from), std::nullopt);
}

bool PostgresJobStore::end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms,
                               const std::string& stop_reason, const std::string& error) {
  std::lock_guard lock(mutex_);
  return move(id, to, now_ms, stop_reason, error, sql_states_into(to, JobState::kRunning), epoch);
}

bool PostgresJobStore::move(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                            const std::string& error, const std::string& from_states, std::optional<int64_t> epoch) {
  if (from_states.empty()) return false;
  Params params{id};
  std::string where = " WHERE id = $1 AND state IN (" + from_states + ")";
  auto param = [&](std::string value) { return placeholder(params, std::move(value)); };
  if (epoch) where += " AND epoch = " + param(to_text(*epoch));
  // Out of running, the lease ends with the run.
  if (to == JobState::kQueued)
    return exec(
               "UPDATE tessera_jobs SET state = 'queued', node = NULL, lease_expires_at = NULL, started_at = NULL, "
               "finished_at = NULL, stop_reason = NULL, error = NULL, passes = 0, samples_done = 0, elapsed_s = 0, "
               "eta_s = NULL, samples_per_s = 0" +
                   where,
               params)
               .affected() > 0;
  if (to == JobState::kRunning) {
    const std::string started = param(to_text(now_ms));
    return exec("UPDATE tessera_jobs SET state = 'running', node = " + param(node_) + ", started_at = " + started +
                    where,
                params)
               .affected() > 0;
  }
  if (to == JobState::kPaused)
    return exec("UPDATE tessera_jobs SET state = 'paused', node = NULL, lease_expires_at = NULL, eta_s = NULL" + where,
                params)
               .affected() > 0;
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
  if (only_finished_before_ms)
    return exec("DELETE FROM tessera_jobs WHERE id = $1 AND state IN (" + sql_terminal_states() +
                    ") AND finished_at < $2",
                {id, to_text(*only_finished_before_ms)})
               .affected() > 0;
  return exec("DELETE FROM tessera_jobs WHERE id = $1", {id}).affected() > 0;
}

int PostgresJobStore::requeue_running() {
  std::lock_guard lock(mutex_);
  return exec(
             "UPDATE tessera_jobs SET state = 'queued', node = NULL, lease_expires_at = NULL, started_at = NULL, "
             "passes = 0, samples_done = 0, elapsed_s = 0, eta_s = NULL, samples_per_s = 0 "
             "WHERE state = 'running' AND node = $1",
             {node_})
      .affected();
}

}  // namespace tessera::server
