// What the SQL job stores (SQLite, PostgreSQL) share: the columns a job record is read from, in one order, and the
// state lists of their WHERE clauses, taken from the state table (job_state.h) so that a store accepts exactly the
// moves it allows. Placeholders differ between the two dialects, so the statements themselves stay with each store.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "server/store/job_state.h"
#include "server/store/job_store.h"

namespace tessera::server {

// The columns read_job_record() reads, in its order; the document, when asked for, follows them.
inline constexpr const char* kJobColumns =
    "id, kind, state, priority, created_at, started_at, finished_at, settings, outputs, passes, samples_done, "
    "samples_total, elapsed_s, eta_s, samples_per_s, stop_reason, error, seq, owner, warnings, idempotency_key, "
    "request_hash, name, epoch, lease_expires_at, node, lost_runs";
inline constexpr int kJobDocumentColumn = 27;

// States as an SQL list, 'queued','paused' (names from the enum, never client text).
inline std::string sql_state_list(const std::vector<JobState>& states) {
  std::string out;
  for (JobState s : states) out += (out.empty() ? "'" : ",'") + std::string(job_state_name(s)) + "'";
  return out;
}

// The SQL list of the states `to` may be reached from, as the state table decides (only `only_from`, when given);
// empty when there are none.
inline std::string sql_states_into(JobState to, std::optional<JobState> only_from) {
  std::vector<JobState> from = states_into(to);
  if (only_from) std::erase_if(from, [&](JobState s) { return s != *only_from; });
  return sql_state_list(from);
}

// The SQL list of the terminal states.
inline std::string sql_terminal_states() {
  std::vector<JobState> terminal;
  for (JobState st : kAllJobStates)
    if (is_terminal(st)) terminal.push_back(st);
  return sql_state_list(terminal);
}

// A job record from a row of kJobColumns (and the document after them when asked). `Row` reads column i as
// text(i), int64(i), real(i) and is_null(i).
template <typename Row>
JobRecord read_job_record(const Row& row, bool with_document) {
  JobRecord r;
  r.id = row.text(0);
  r.kind = row.text(1);
  r.state = parse_job_state(row.text(2)).value_or(JobState::kFailed);
  r.priority = static_cast<int>(row.int64(3));
  r.created_at_ms = row.int64(4);
  if (!row.is_null(5)) r.started_at_ms = row.int64(5);
  if (!row.is_null(6)) r.finished_at_ms = row.int64(6);
  r.settings = row.text(7);
  r.outputs = row.text(8);
  r.progress.passes = static_cast<uint32_t>(row.int64(9));
  r.progress.samples_done = static_cast<uint32_t>(row.int64(10));
  r.progress.samples_total = static_cast<uint32_t>(row.int64(11));
  r.progress.elapsed_s = row.real(12);
  if (!row.is_null(13)) r.progress.eta_s = row.real(13);
  r.progress.samples_per_s = row.real(14);
  r.stop_reason = row.text(15);
  r.error = row.text(16);
  r.seq = row.int64(17);
  r.owner = row.text(18);
  r.warnings = row.text(19);
  r.idempotency_key = row.text(20);
  r.request_hash = row.text(21);
  r.name = row.text(22);
  r.epoch = row.int64(23);
  if (!row.is_null(24)) r.lease_expires_at_ms = row.int64(24);
  r.node = row.text(25);
  r.lost_runs = static_cast<int>(row.int64(26));
  if (with_document) r.document = row.text(kJobDocumentColumn);
  return r;
}

// How many runs of the owner `owner_sql` names hold a live lease at the time `now_sql` names (a placeholder: $1, ?1):
// jobs rendered whole, and work units, in the tables `jobs` and `units` of a store (the per-owner cap of claim_next).
inline std::string sql_live_runs_of(const std::string& jobs, const std::string& units, const std::string& owner_sql,
                                    const std::string& now_sql) {
  return "((SELECT count(*) FROM " + jobs + " r WHERE r.owner = " + owner_sql +
         " AND r.units = 1 AND r.state = 'running' AND r.lease_expires_at >= " + now_sql +
         ") + (SELECT count(*) FROM " + units + " ru JOIN " + jobs +
         " rj ON rj.id = ru.job_id WHERE rj.owner = " + owner_sql +
         " AND ru.state = 'running' AND ru.lease_expires_at >= " + now_sql + "))";
}

// The columns of a unit row (table alias u) read_unit_record() reads, in its order.
inline constexpr const char* kUnitColumns =
    "u.idx, u.first_sample, u.samples, u.state, u.checkpoint_epoch, COALESCE(u.node, ''), u.samples_done, "
    "u.elapsed_s, u.samples_per_s, COALESCE(u.renewed_at, 0), COALESCE(u.lease_expires_at, 0)";

// A unit from a row of kUnitColumns; `Row` as read_job_record()'s.
template <typename Row>
UnitRecord read_unit_record(const Row& row) {
  UnitRecord u;
  u.index = static_cast<int>(row.int64(0));
  u.first_sample = static_cast<uint32_t>(row.int64(1));
  u.samples = static_cast<uint32_t>(row.int64(2));
  u.done = row.text(3) == "done";
  u.running = row.text(3) == "running";
  u.checkpoint_epoch = row.int64(4);
  u.node = row.text(5);
  u.samples_done = static_cast<uint32_t>(row.int64(6));
  u.elapsed_s = row.real(7);
  u.samples_per_s = row.real(8);
  if (u.running) {
    u.renewed_at_ms = row.int64(9);
    u.lease_expires_at_ms = row.int64(10);
  }
  return u;
}

}  // namespace tessera::server
