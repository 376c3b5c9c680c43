// A job as the API shows it (proto/schemas/job-status.schema.json).
#pragma once

#include <optional>

#include <nlohmann/json.hpp>

#include "server/job_store.h"

namespace tessera::server {

// `live` (from the scheduler) replaces the stored progress of a running job when given; `queue_position` is shown
// while the job is queued.
nlohmann::json job_status_json(const JobRecord& job, const std::optional<JobProgress>& live = std::nullopt,
                               std::optional<int> queue_position = std::nullopt);

}  // namespace tessera::server
