// Where jobs live: a small interface (create, claim, update, finish, get, list, remove) so the SQLite store of one
// daemon can later be replaced by a queue several daemons share. Nothing outside a store implementation knows how
// jobs are kept. Every state change goes through can_transition() (job_state.h). A store that fails throws
// JobStoreError, so that callers can tell a store that could not record something from a job that went wrong.
#pragma once

#include <algorithm>
#include <cstdint>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "server/store/job_state.h"

namespace tessera::server {

struct JobProgress {
  uint32_t passes = 0;
  uint32_t samples_done = 0;   // per pixel
  uint32_t samples_total = 0;  // per pixel, the budget
  double elapsed_s = 0;
  std::optional<double> eta_s;  // unknown before the first pass
  double samples_per_s = 0;     // pixel samples per second
};

struct JobRecord {
  int64_t seq = 0;  // submission order, set by the store; the cursor of paginated lists
  std::string id;
  std::string name;  // what its owner calls it (the document's "name", else the file or materials it renders)
  std::string kind;  // "scene" | "material"
  JobState state = JobState::kQueued;
  int priority = 0;
  int64_t created_at_ms = 0;  // Unix time, milliseconds
  std::optional<int64_t> started_at_ms;
  std::optional<int64_t> finished_at_ms;
  std::string document;  // the submitted job JSON; filled by get(..., with_document) and claim_next()
  std::string settings;  // the render settings as JSON, defaults filled in
  std::string outputs;   // JSON array of "png" / "exr"
  JobProgress progress;
  std::string stop_reason;      // empty until the render ends
  std::string error;            // empty unless failed
  std::string owner;            // the token name of who submitted it; empty without tokens
  std::string warnings;         // JSON array of strings (unsupported optional glTF extensions, ...)
  std::string idempotency_key;  // the client's Idempotency-Key, empty if none
  std::string request_hash;     // sha256 of the request the key came with
  // The lease of the run under way: who renders it, until when, and the epoch each claim advances. Every write of a
  // run carries its epoch, and the store refuses one of an older epoch (fencing: a node that was paused or cut off
  // past its lease cannot write over the node that took the job over).
  int64_t epoch = 0;
  std::string node;
  std::optional<int64_t> lease_expires_at_ms;
  // Runs of the job that were lost: the process rendering it (or one of its units) died without ending its run, found
  // when its node restarts (requeue_running) or another node takes the run over after its lease expired
  // (claim_next). The scheduler fails a job lost more often than it allows, rather than let a scene that crashes the
  // renderer take down every node that claims it, at every start. A requeue of an ended job starts the count over.
  int lost_runs = 0;
  // Set by a claim that took the run over from a node whose lease expired: that node's name.
  std::string taken_over_from;
  // Work units (work_units.h): how many the job's samples are split into (1: the job renders whole), set at
  // submission. A claim of one unit fills the rest: its index (units itself: the merge of the others' films), its
  // sample range, and the epoch of the run whose checkpoint is the unit's authoritative one (0: none yet). Its
  // `epoch` is then the unit run's: the job's epoch counter hands out the fencing tokens of all its units.
  int units = 1;
  int unit = -1;  // -1: the claim is of the whole job
  uint32_t unit_first_sample = 0;
  uint32_t unit_samples = 0;
  int64_t unit_checkpoint_epoch = 0;
  // The runs of the claimed unit that were lost (as lost_runs counts the job's): a frame of a range is retried on its
  // own count, so that the frames of a long range do not share one.
  int unit_lost_runs = 0;

  // It failed because the renderer refused its input (job_state.h): running it again would fail the same way.
  bool input_refused() const { return state == JobState::kFailed && stop_reason == kInputRefused; }
};

struct JobFilter {
  std::optional<JobState> state;
  std::vector<JobState> states;               // any of these (with `state`, its union)
  std::optional<std::string> owner;           // only this owner's jobs
  std::optional<int64_t> before_seq;          // only jobs submitted before this one (cursor)
  std::optional<int64_t> finished_before_ms;  // only jobs that ended before this time (retention)
  int limit = 100;
};

// The store itself failed (a full disk, a database locked too long, an I/O error): the request may succeed once
// the store recovers, and it says nothing about the job. Every error of a store is one of these.
class JobStoreError : public std::runtime_error {
 public:
  JobStoreError(const std::string& what, bool out_of_space) : std::runtime_error(what), out_of_space_(out_of_space) {}
  // The store ran out of room (a full disk or quota, a file-size limit): a client may retry once space is freed.
  bool out_of_space() const { return out_of_space_; }

 private:
  bool out_of_space_;
};

// How long a claim holds a job without being renewed; a render renews its lease about every second.
inline constexpr int64_t kDefaultLeaseMs = 30000;
// How often a node renews each lease it holds: a quarter of the lease, at least once a second. A node that misses a
// renewal or two still holds most of its lease, and another can tell from the time of the last renewal
// (UnitRecord::renewed_at_ms) that the node stopped: three periods without one.
constexpr int64_t lease_renewal_period_ms(int64_t lease_ms) {
  return std::clamp<int64_t>(lease_ms / 4, 1, 1000);
}
constexpr int64_t lease_stall_ms(int64_t lease_ms) {
  return 3 * lease_renewal_period_ms(lease_ms);
}

// One unit of a split job, as the merge and the preview read them.
struct UnitRecord {
  int index = 0;
  uint32_t first_sample = 0;
  uint32_t samples = 0;
  bool done = false;
  int64_t checkpoint_epoch = 0;  // the run whose checkpoint (a done unit's: its film) is authoritative; 0: none
  // What the job's status shows of it: running (or else queued, when not done), on which node, and its progress as
  // of its last checkpoint (samples per pixel of its range, render seconds, pixel samples per second).
  bool running = false;
  std::string node;
  uint32_t samples_done = 0;
  double elapsed_s = 0;
  double samples_per_s = 0;
  // A running unit's lease: when its node last renewed it and when it runs out (milliseconds since the epoch, the
  // renewing node's clock; 0 when not known). A node that stopped renewing (it died, or is cut off) holds the unit
  // until the lease runs out; then another node takes it over from its checkpoint.
  int64_t renewed_at_ms = 0;
  int64_t lease_expires_at_ms = 0;
};

class JobStore {
 public:
  virtual ~JobStore() = default;

  // Adds a queued job. Throws if the id exists.
  virtual void create(const JobRecord& job) = 0;
  // Takes the next job to render (highest priority, then first come): a queued one, or a running one whose lease
  // expired (its node stopped renewing it: it died, or was paused or cut off), which counts a lost run. Marks it
  // running under a new lease: the next epoch, expiring at now_ms + lease_ms, this store's node. Nothing when none
  // waits. With `max_running_per_owner` above 0, jobs of an owner whose runs under a live lease already number that
  // many are passed over (a run: a job rendered whole, or one work unit of a split job), whichever node holds them: a
  // user cannot take every render slot of the cluster, and never holds more than that many, however many nodes claim at
  // once.
  virtual std::optional<JobRecord> claim_next(int64_t now_ms, int64_t lease_ms = kDefaultLeaseMs,
                                              int max_running_per_owner = 0) = 0;
  // Extends the lease of a run to now_ms + lease_ms; false when the run is no longer this epoch's (the job was
  // claimed again, ended, paused, cancelled or deleted elsewhere): its render must stop and write nothing more.
  virtual bool renew_lease(const std::string& id, int64_t epoch, int64_t now_ms, int64_t lease_ms) = 0;
  // Records the progress of a run of this epoch; false (and nothing written) when the run is no longer this epoch's.
  virtual bool update_progress(const std::string& id, int64_t epoch, const JobProgress& progress) = 0;
  // Ends a run of this epoch: running -> `to` (succeeded, failed, cancelled, paused, or queued to resume elsewhere), as
  // transition() does; false (nothing written) when the job is not running under this epoch.
  virtual bool end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms,
                       const std::string& stop_reason = "", const std::string& error = "") = 0;
  // Moves a job to `to` if can_transition() allows it from its current state (and that state is `only_from`, when
  // given); false otherwise (or unknown id). A terminal state stamps finished_at; back to queued clears the run's
  // progress, its end and its error.
  virtual bool transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason = "",
                          const std::string& error = "", std::optional<JobState> only_from = std::nullopt) = 0;
  // Changes the priority of a job that has not ended; false for an unknown or ended job.
  virtual bool set_priority(const std::string& id, int priority) = 0;
  virtual void set_warnings(const std::string& id, const std::string& warnings_json) = 0;
  // 1-based place of a queued job in the claim order; nothing when it is not queued.
  virtual std::optional<int> queue_position(const std::string& id) = 0;
  // The job created with this owner and Idempotency-Key, if any.
  virtual std::optional<JobRecord> find_by_idempotency_key(const std::string& owner, const std::string& key) = 0;
  // Jobs per state; with `owner`, only theirs.
  virtual std::map<JobState, int> count_by_state(const std::optional<std::string>& owner = std::nullopt) = 0;
  virtual std::optional<JobRecord> get(const std::string& id, bool with_document = false) = 0;
  // Newest first (by seq).
  virtual std::vector<JobRecord> list(const JobFilter& filter) = 0;
  // Deletes a job; with `only_finished_before_ms`, only if it has ended (succeeded, failed, cancelled) before that
  // time, checked in the same step (a job requeued meanwhile is kept). False when nothing was deleted.
  virtual bool remove(const std::string& id, std::optional<int64_t> only_finished_before_ms = std::nullopt) = 0;
  // Puts jobs left running by a previous process back in the queue, each counting a lost run; returns how many.
  virtual int requeue_running() = 0;

  // Work units (JobRecord::units). A store creates a job's units with it when job.units > 1 (job.units of them, their
  // samples as unit_sample_ranges() gives them, and the merge unit: a frame range's units on every store, a still's
  // sample ranges on a store that splits jobs), claims them in claim_next() as it claims jobs, and
  // fences each unit run by its epoch in renew_lease(), update_progress() (which also records the run's checkpoint as
  // the unit's authoritative one) and end_run() (succeeded: the unit is done; the merge unit's end is the job's).
  // A store that does not split stills renders every still whole.
  virtual bool splits_jobs() const { return false; }
  // The units of a job (not its merge unit), by index; empty for a job rendered whole.
  virtual std::vector<UnitRecord> units(const std::string& /*id*/) { return {}; }
};

}  // namespace tessera::server
