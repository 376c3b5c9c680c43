// The HTTP API of tesserad (proto/openapi.json): routes, answers, and problem+json for every error, including the
// ones cpp-httplib produces itself (unknown route, body too large) and any exception a handler lets out. Bearer
// tokens, CORS, Server-Sent Events, metrics and the request limits live here; rendering does not.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "renderer/thread_pool.h"
#include "server/assets.h"
#include "server/auth.h"
#include "server/events.h"
#include "server/job_files.h"
#include "server/job_store.h"
#include "server/metrics.h"
#include "server/scheduler.h"
#include "server/submission.h"

namespace httplib {
class Server;
}

namespace tessera::server {

struct ApiContext {
  JobStore& store;
  const JobFiles& files;
  Scheduler& scheduler;
  AssetStore& assets;
  EventHub& events;
  Auth& auth;
  Metrics& metrics;
  const ThreadPool* pool = nullptr;  // for the busy-threads gauge
  SubmissionLimits limits;
  size_t max_body_bytes = 64u << 20;
  int max_user_priority = 100;
  int max_queued_per_user = 0;
  std::vector<std::string> cors_origins;
  int keepalive_s = 15;
  // Requests that store client data (jobs, assets) are refused with 507 while the filesystem of `data_dir` has
  // less than this available to the daemon; 0: never.
  uint64_t min_free_disk_bytes = 0;
  std::filesystem::path data_dir;
};

// Every route the API serves, as OpenAPI names it ("/v1/jobs/{id}"), for the test that holds the two in step.
struct RouteInfo {
  std::string method;  // "GET", "POST", "PATCH", "DELETE"
  std::string path;
};
std::vector<RouteInfo> api_routes();

// Registers the routes and the error, exception and logging handlers on `server`, and the scheduler hooks that
// feed the event streams and metrics. `ctx` must outlive both.
void install_api(httplib::Server& server, ApiContext& ctx);

// Deletes a job as DELETE /v1/jobs/{id} does: its render stopped, its files and store row gone, its event history
// forgotten. With `only_finished_before_ms` (the retention sweep), only a job that ended before that time; false when
// nothing was deleted.
bool remove_job(ApiContext& ctx, const std::string& id, std::optional<int64_t> only_finished_before_ms = std::nullopt);

// The asset resolver jobs use: a 64-hex asset id to its main file; anything else is a SceneError at `pointer`.
std::function<std::filesystem::path(const std::string&, const std::string&)> asset_resolver(const AssetStore& assets);

}  // namespace tessera::server
