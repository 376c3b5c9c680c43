// The job store of one daemon: SQLite in WAL mode in the data directory. One connection behind a mutex; each statement
// prepared once; a schema version table so later versions can migrate.
#pragma once

#include <filesystem>
#include <mutex>
#include <string>
#include <unordered_map>

#include "server/store/job_store.h"

struct sqlite3;
struct sqlite3_stmt;

namespace tessera::server {

class SqliteJobStore final : public JobStore {
 public:
  // Opens (creating if needed) the database file. Every method throws JobStoreError when SQLite fails.
  explicit SqliteJobStore(const std::filesystem::path& file);
  ~SqliteJobStore() override;
  SqliteJobStore(const SqliteJobStore&) = delete;
  SqliteJobStore& operator=(const SqliteJobStore&) = delete;

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
  std::vector<UnitRecord> units(const std::string& id) override;

  static constexpr int kSchemaVersion = 6;

 private:
  class Statement;
  struct CachedStatement {
    sqlite3_stmt* stmt = nullptr;
    bool in_use = false;
  };
  // transition() and end_run(): a move into `to` from `from_states` (an SQL list), of the run of `epoch` when given.
  bool move(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
            const std::string& error, const std::string& from_states, std::optional<int64_t> epoch);
  void exec(const char* sql);
  // Runs `body` in one write transaction (BEGIN IMMEDIATE): a claim, an end, a creation of units.
  template <typename F>
  auto in_transaction(F&& body);
  // Claims unit `idx` of job `job_id` (`lost`: taken over from a run whose lease expired), in claim_next().
  JobRecord claim_unit(const std::string& job_id, int64_t idx, bool lost, int64_t now_ms, int64_t lease_ms);
  // The progress of a job of units over all its units (as PostgresJobStore::aggregate_units).
  void aggregate_units(const std::string& id);
  void migrate();
  void close();

  std::mutex mutex_;
  sqlite3* db_ = nullptr;
  std::unordered_map<std::string, CachedStatement> statements_;  // prepared statements by SQL text, under mutex_
};

}  // namespace tessera::server
