// The HTTP API of tesserad (proto/openapi.json): routes that parse a request, call the job service (or the asset
// store) and answer, with problem+json for every error, including the ones cpp-httplib produces itself (unknown route,
// body too large) and any exception a handler lets out. Bearer tokens, CORS, Server-Sent Events, metrics and the
// request limits live here; the rules of jobs live in the job service, rendering in the scheduler.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "renderer/thread_pool.h"
#include "server/base/auth.h"
#include "server/files/assets.h"
#include "server/files/events.h"
#include "server/http/http_transport.h"
#include "server/jobs/job_service.h"
#include "server/jobs/metrics.h"
#include "server/jobs/submission.h"

namespace httplib {
class Server;
}

namespace tessera::server {

struct ApiContext {
  JobService& jobs;
  AssetStore& assets;
  EventBus& events;
  Auth& auth;
  Metrics& metrics;
  const ThreadPool* pool = nullptr;  // for the busy-threads gauge
  SubmissionLimits limits;
  size_t max_body_bytes = 64u << 20;
  std::vector<std::string> cors_origins;
  int keepalive_s = 15;
  // Requests that store client data (jobs, assets) are refused with 507 while the filesystem of `data_dir` has
  // less than this available to the daemon; 0: never.
  uint64_t min_free_disk_bytes = 0;
  std::filesystem::path data_dir;
  const HttpTransport* transport = nullptr;  // for the connection gauges (none when served by a plain httplib::Server)
  // Whether the store's notifications arrive (PostgresNotifications::connected), for its gauge; unset on a store
  // that has none (SQLite).
  std::function<bool()> store_notifications_up{};
};

// Every route the API serves, as OpenAPI names it ("/v1/jobs/{id}"), for the test that holds the two in step.
struct RouteInfo {
  std::string method;  // "GET", "POST", "PATCH", "DELETE"
  std::string path;
};
std::vector<RouteInfo> api_routes();

// Whether a request target ("/v1/jobs/{id}/events?access_token=...") is an event stream: a long-lived response.
bool is_event_stream_target(std::string_view target);

// Registers the routes and the error, exception and logging handlers on `server`. `ctx` must outlive it.
void install_api(httplib::Server& server, ApiContext& ctx);

}  // namespace tessera::server
