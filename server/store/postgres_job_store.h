// The job store in a PostgreSQL database (libpq), which several daemons may share: `--store postgresql://...`.
// The schema is versioned: at start-up each daemon runs the migrations it knows and the database lacks, one daemon at
// a time (a session-level advisory lock), and refuses a database a newer daemon migrated. Claims take the next job
// with SELECT ... FOR UPDATE SKIP LOCKED, so daemons claiming at once never take the same job nor wait for each other.
// Every state change is one UPDATE whose WHERE names the states the state table allows the move from, so a move
// another daemon made first (a cancel) is never overwritten (the update matches no row: false). A job claimed is
// stamped with the claiming daemon's node name; requeue_running() puts back only this node's jobs.
// One connection behind a mutex; a connection that broke (the server restarted) is opened again at the next call,
// the call that found it broken failing with JobStoreError.
#pragma once

#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "server/store/job_store.h"
#include "server/store/postgres_connection.h"

namespace tessera::server {

class PostgresJobStore final : public JobStore {
 public:
  // Connects (a libpq connection string or URI), migrates. Throws JobStoreError when the database cannot be reached
  // or has a newer schema. `node` names this daemon in the jobs it claims. A transaction of this store idle for
  // `idle_transaction_limit_ms` (the daemon's lease; 0: the server's setting) is ended by the server with its locks:
  // a node stopped mid-transaction then holds up the others no longer than its lease would (PgConnection).
  PostgresJobStore(const std::string& conninfo, std::string node, int64_t idle_transaction_limit_ms = 0);
  ~PostgresJobStore() override;
  PostgresJobStore(const PostgresJobStore&) = delete;
  PostgresJobStore& operator=(const PostgresJobStore&) = delete;

  void create(const JobRecord& job) override;
  std::optional<JobRecord> claim_next(int64_t now_ms, int64_t lease_ms = kDefaultLeaseMs,
                                      int max_running_per_owner = 0) override;
  bool renew_lease(const std::string& id, int64_t epoch, int64_t now_ms, int64_t lease_ms) override;
  bool update_progress(const std::string& id, int64_t epoch, const JobProgress& progress) override;
  bool end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms, const std::string& stop_reason = "",
               const std::string& error = "") override;
  bool transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                  const std::string& error, std::optional<JobState> only_from = std::nullopt) override;
  bool set_priority(const std::string& id, int priority) override;
  void set_warnings(const std::string& id, const std::string& warnings_json) override;
  std::optional<int> queue_position(const std::string& id) override;
  std::optional<JobRecord> find_by_idempotency_key(const std::string& owner, const std::string& key) override;
  std::map<JobState, int> count_by_state(const std::optional<std::string>& owner) override;
  std::optional<JobRecord> get(const std::string& id, bool with_document) override;
  std::vector<JobRecord> list(const JobFilter& filter) override;
  bool remove(const std::string& id, std::optional<int64_t> only_finished_before_ms = std::nullopt) override;
  int requeue_running() override;
  bool splits_jobs() const override { return true; }
  std::vector<UnitRecord> units(const std::string& id) override;

  // The migrations, in order: schema version N is reached by running kMigrations[N - 1].
  static const std::vector<const char*>& migrations();
  static int schema_version() { return static_cast<int>(migrations().size()); }

 private:
  class Result;
  using Params = PgConnection::Params;
  // Runs one statement with text parameters ($1, $2, ...; nothing is NULL); throws JobStoreError on failure.
  Result exec(const std::string& sql, const Params& params = {});
  // transition() and end_run(): a move into `to` from `from_states` (an SQL list), of the run of `epoch` when given.
  bool move(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
            const std::string& error, const std::string& from_states, std::optional<int64_t> epoch);
  void migrate();
  // Runs `body` in one transaction: committed when it returns, rolled back when it throws.
  template <typename F>
  auto in_transaction(F&& body);
  void aggregate_units(const std::string& id);

  std::string node_;
  std::mutex mutex_;
  PgConnection conn_;
};

}  // namespace tessera::server
