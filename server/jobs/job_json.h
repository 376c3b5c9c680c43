// A job as the API shows it (proto/schemas/job-status.schema.json).
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <nlohmann/json.hpp>

#include "server/store/job_store.h"

namespace tessera::server {

// `live` (from the scheduler) replaces the stored progress of a running job when given; `queue_position` is shown
// while the job is queued. A job split into work units shows `units`, its units as the store has them (JobStore::units)
// (done, running where, waiting), and its progress in wall time (from its start to `now`, the clock's when 0, or to its
// end) beside the render time its units took on all nodes together.
nlohmann::json job_status_json(const JobRecord& job, const std::optional<JobProgress>& live = std::nullopt,
                               std::optional<int> queue_position = std::nullopt,
                               const std::vector<UnitRecord>& units = {}, int64_t now = 0);

}  // namespace tessera::server
