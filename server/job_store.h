// Where jobs live: a small interface (create, claim, update, finish, get, list, remove) so the SQLite store of one
// daemon can later be replaced by a queue several daemons share. Nothing outside a store implementation knows how
// jobs are kept. Every state change goes through can_transition() (job_state.h).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "server/job_state.h"

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
  std::string id;
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
  std::string stop_reason;  // empty until the render ends
  std::string error;        // empty unless failed
};

struct JobFilter {
  std::optional<JobState> state;
  int limit = 100;
};

class JobStore {
 public:
  virtual ~JobStore() = default;

  // Adds a queued job. Throws if the id exists.
  virtual void create(const JobRecord& job) = 0;
  // Takes the next queued job (highest priority, then first come) and marks it running; nothing when none waits.
  virtual std::optional<JobRecord> claim_next(int64_t now_ms) = 0;
  // Records the progress of a running job.
  virtual void update_progress(const std::string& id, const JobProgress& progress) = 0;
  // Moves a job to `to` if can_transition() allows it from its current state; false otherwise (or unknown id).
  // A terminal state stamps finished_at; back to queued clears the run's progress.
  virtual bool transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason = "",
                          const std::string& error = "") = 0;
  virtual std::optional<JobRecord> get(const std::string& id, bool with_document = false) = 0;
  // Newest first.
  virtual std::vector<JobRecord> list(const JobFilter& filter) = 0;
  virtual bool remove(const std::string& id) = 0;
  // Puts jobs left running by a previous process back in the queue; returns how many.
  virtual int requeue_running() = 0;
};

}  // namespace tessera::server
