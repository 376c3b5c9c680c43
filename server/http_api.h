// The HTTP API of tesserad (proto/openapi.json): routes, answers, and problem+json for every error, including the
// ones cpp-httplib produces itself (unknown route, body too large) and any exception a handler lets out.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "server/job_files.h"
#include "server/job_store.h"
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
  SubmissionLimits limits;
  size_t max_body_bytes = 64u << 20;
};

// Every route the API serves, as OpenAPI names it ("/v1/jobs/{id}"), for the test that holds the two in step.
struct RouteInfo {
  std::string method;  // "GET", "POST", "DELETE"
  std::string path;
};
std::vector<RouteInfo> api_routes();

// Registers the routes and the error, exception and logging handlers on `server`. `ctx` must outlive it.
void install_api(httplib::Server& server, ApiContext& ctx);

}  // namespace tessera::server
