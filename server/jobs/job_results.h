// A job's results as files: the outputs a run encodes from its film, the partial results a cancelled job keeps, and
// the film of a split job's units. Outputs are staged (JobFiles::stage) under a key, the epoch of the run they belong
// to or a cancel's own, and published over the names clients read by settle_staged() only once the store took the
// end they belong to: an end the store refuses (the job changed meanwhile) leaves what clients read as it was. The
// scheduler uses it for the ends of the runs it renders; the job service for a client's cancel.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "renderer/film.h"
#include "renderer/output.h"
#include "server/files/job_files.h"
#include "server/files/job_log.h"
#include "server/store/job_store.h"

namespace tessera::server {

// What a unit's checkpoints are checked against: the job's render settings and the unit, so that one unit's film is
// never read as another's.
uint64_t unit_settings_hash(const std::string& settings, int unit);

// The outputs a job asked for (result.png, result.exr, its passes' PNGs), encoded from `image`
// (OutputPipeline::image) and staged under `key` for JobResults::settle_staged(); the names written, for its log.
std::string stage_outputs(const JobFiles& files, const std::string& id, const OutputPipeline& outputs,
                          const Image& image, int64_t key);

class JobResults {
 public:
  // `node`: this daemon's name among the nodes sharing the store, for the lines it adds to job logs (JobLog).
  JobResults(JobStore& store, const JobFiles& files, std::string node = "");

  // The result files staged under `key`: published over the final names, or removed.
  void settle_staged(const std::string& id, int64_t key, bool publish) const;
  // The film of a split job's units: the done ones, with `in_progress` also the last checkpoints of the others
  // (samples rendered, not a contiguous range: an unbiased, noisier image). Nothing for a job rendered whole or when
  // no unit has a film; throws when a done unit's film is missing or damaged.
  std::optional<Film> merge_unit_films(const JobRecord& job, int width, int height, bool in_progress) const;
  // A client's cancel of `job` (read just now, in a state that allows it), recorded in the store. What it rendered,
  // its checkpoint's film (the image of its last complete pass) or its units' films, is staged as its partial results
  // before the store says cancelled, and published once the store took the change: a cancel that loses the race
  // with the run's own end (refused: the job succeeded meanwhile) never puts its older image over the finished one.
  // The key is negative, unlike any run's epoch (a run elsewhere stages its own outputs under its epoch), and drawn
  // at random, so that two nodes cancelling at once stage apart. False when the store refused the change.
  bool record_cancel(const JobRecord& job) const;

 private:
  // The partial results of `job` staged under `key`. Best effort: nothing without a usable film; a file that cannot
  // be written is logged, and the cancel goes on.
  void stage_partial_results(const JobRecord& job, int64_t key) const;

  JobStore& store_;
  const JobFiles& files_;
  JobLog log_;
};

}  // namespace tessera::server
