// The jobs as clients see them: submitting (idempotency keys, per-user caps, priority rules), reading with
// visibility (a user sees only their own jobs; an admin every job), the actions of the state table (job_state.h), the
// files a job shows, deletion. The HTTP routes, the scheduler's hooks (events and metrics of a render) and the
// retention sweep all go through it; it goes to the job store, the job files and the scheduler. It knows nothing of
// HTTP: a refusal is a Problem for the caller to answer. A client's change of a job's state is its to decide and
// record, no claim of this daemon's scheduler meanwhile: the store's change first (with a cancelled job's partial
// results, JobResults), then, for a cancel or pause, a stop signal to the renders of the job here (Scheduler::stop),
// which end within a tile's time and record nothing.
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "server/base/auth.h"
#include "server/base/problem.h"
#include "server/files/assets.h"
#include "server/files/events.h"
#include "server/files/job_files.h"
#include "server/files/job_log.h"
#include "server/jobs/job_results.h"
#include "server/jobs/metrics.h"
#include "server/jobs/scheduler.h"
#include "server/jobs/submission.h"
#include "server/store/job_state.h"
#include "server/store/job_store.h"

namespace tessera::server {

struct JobServiceOptions {
  int max_user_priority = 100;  // above it, only an admin may set a priority
  int max_queued_per_user = 0;  // queued jobs a user may have; 0: no cap
  // Work units (work_units.h): about this many pixel samples each, on a store that splits jobs; 0: never split.
  uint64_t unit_pixel_samples = 0;
  // This daemon's name among the nodes sharing the store, for the lines it adds to job logs (JobLog).
  std::string node;
};

struct SubmitRequest {
  AcceptedJob job;
  std::string idempotency_key;  // empty: none
  std::string request_hash;     // a key reused with another request is refused
  bool files_stored = false;    // the files of a multipart submission are stored already (said when the job is not)
};

struct Submitted {
  JobRecord job;
  nlohmann::json status;
  bool created = false;  // false: an earlier request with the same Idempotency-Key made it
};

// A job after an action.
struct ActionTaken {
  JobRecord job;
  nlohmann::json status;
};

struct JobPage {
  std::vector<nlohmann::json> jobs;        // statuses, newest first
  std::optional<int64_t> next_before_seq;  // where the next page starts; nothing on the last page
};

class JobService {
 public:
  // Installs the scheduler's hooks; the scheduler is shut down when the service goes.
  JobService(JobStore& store, const JobFiles& files, AssetStore& assets, Scheduler& scheduler, EventBus& events,
             Metrics& metrics, JobServiceOptions options);
  ~JobService();
  JobService(const JobService&) = delete;
  JobService& operator=(const JobService&) = delete;

  // Stores the files uploaded with a job as assets (the environment map it names as one, the rest as its glTF asset)
  // and puts their ids in the document in place of the file names. A reference to a file the request did not send
  // (no asset id, no file of that name) is a 422 naming that file.
  std::optional<Problem> store_uploads(const Caller& caller, nlohmann::json& document, std::vector<UploadFile> files);
  // Queues a checked job, or answers with the job an earlier request with the same Idempotency-Key made.
  std::variant<Submitted, Problem> submit(const Caller& caller, SubmitRequest request);

  // The job if it exists and the caller may see it: an id of the wrong shape, or another user's job, is unknown.
  std::optional<JobRecord> find(const Caller& caller, const std::string& id);
  // The job as the API shows it (job-status.schema.json), with the live progress of a render and a queued job's
  // place.
  nlohmann::json status(const JobRecord& job);
  // The caller's jobs (an admin's: every job), newest first, `filter.limit` of them from `filter.before_seq`.
  JobPage list(const Caller& caller, JobFilter filter);
  std::map<JobState, int> counts();

  // The latest progressive image, or why there is none.
  std::variant<std::unique_ptr<FileReader>, Problem> preview(const JobRecord& job);
  // The document the job was accepted with (JSON text): its uploaded files named by their asset ids.
  std::optional<std::string> document(const JobRecord& job);
  // The job's log (job_log.h); null before it has one (it has not started rendering).
  std::unique_ptr<FileReader> job_log(const JobRecord& job);
  // A finished output (kResultPng or kResultExr), or why there is none.
  std::variant<std::unique_ptr<FileReader>, Problem> result(const JobRecord& job, JobFile file);
  // A finished job's render pass `name` (render.aovs) as PNG, or why there is none (404 naming the job's passes for
  // a pass it did not ask for).
  std::variant<std::unique_ptr<FileReader>, Problem> pass(const JobRecord& job, std::string_view name);
  // Frame `frame` (its number as the path gives it) of a frame range job: its output `file` (kResultPng,
  // kResultExr) or, with `pass`, that render pass's PNG; 404 naming the range for a frame not in it (or not a frame
  // number), for a frame not done yet, and for a job that renders no range.
  std::variant<std::unique_ptr<FileReader>, Problem> frame_result(const JobRecord& job, std::string_view frame,
                                                                  JobFile file, std::string_view pass = {});

  // Cancel, pause, resume or requeue (409 with the state table's reason when the job's state does not allow it; 429
  // when resuming or requeueing would queue more of the owner's jobs than --max-queued-per-user).
  std::variant<ActionTaken, Problem> act(const JobRecord& job, JobAction action);
  std::variant<ActionTaken, Problem> set_priority(const Caller& caller, const JobRecord& job, int priority);
  // Deletes a job: its render stopped, its files and record gone, its events forgotten. With
  // `only_finished_before_ms` (the retention sweep), only a job that ended before that time; false when nothing was
  // deleted.
  bool remove(const std::string& id, std::optional<int64_t> only_finished_before_ms = std::nullopt);

  // New jobs are taken (false while starting or shutting down).
  bool accepting() const;
  // The end of a render is waiting for the store to take it, or the store refused the last client's change.
  bool store_failing() const;

 private:
  // A result file of a succeeded or cancelled job, published by its run's end (or by this call, where the node that
  // ended the run stopped before publishing it), or why there is none.
  std::variant<std::unique_ptr<FileReader>, Problem> published_result(const JobRecord& job, JobFile file);
  // Runs a client's change (submit, act, set_priority, remove) and notes whether the store took it: a store that
  // answers reads but refuses writes is failing all the same (/readyz, tessera_job_store_up), until a change goes
  // through again. A JobStoreError goes on to the caller.
  template <typename Fn>
  auto writing(Fn&& change) -> decltype(change()) {
    try {
      auto result = change();
      writes_failing_.store(false);
      return result;
    } catch (const JobStoreError&) {
      writes_failing_.store(true);
      throw;
    }
  }
  void publish_state(const std::string& id);
  // 429 when `owner` has --max-queued-per-user jobs queued already.
  std::optional<Problem> queue_full(const std::string& owner);
  std::variant<ActionTaken, Problem> taken(const std::string& id);
  // A client's change of a job's state, as act() answers it.
  enum class Outcome { kDone, kConflict, kUnknown };
  Outcome change_state(const std::string& id, JobAction action);
  // queued, paused or running -> cancelled: a job cancelled after a pass keeps the image of its last complete pass
  // (or its units' films) as its results (partial); its renders here stop.
  Outcome cancel(const std::string& id);
  // queued or running -> paused: its renders here stop, and the job keeps its checkpoint for its resume.
  Outcome pause(const std::string& id);
  // paused -> queued.
  Outcome resume(const std::string& id);
  // failed or cancelled -> queued, from scratch (its checkpoint, preview and outputs are deleted); not a job that
  // failed on its input.
  Outcome requeue(const std::string& id);

  JobStore& store_;
  const JobFiles& files_;
  AssetStore& assets_;
  Scheduler& scheduler_;
  EventBus& events_;
  Metrics& metrics_;
  const JobServiceOptions options_;
  JobLog log_;  // each job's own log, among its files
  JobResults results_;
  std::atomic<bool> writes_failing_{false};
};

}  // namespace tessera::server
