// A job as the API shows it (proto/schemas/job-status.schema.json).
#pragma once

#include <optional>

#include <nlohmann/json.hpp>

#include "server/job_store.h"

namespace tessera::server {

// `live` (from the scheduler) replaces the stored progress of a running job when given.
nlohmann::json job_status_json(const JobRecord& job, const std::optional<JobProgress>& live = std::nullopt);

}  // namespace tessera::server
