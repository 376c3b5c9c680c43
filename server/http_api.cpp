#include "server/http_api.h"

#include <httplib.h>

#include <algorithm>
#include <charconv>
#include <fstream>
#include <functional>
#include <regex>

#include "server/contract.h"
#include "server/job_id.h"
#include "server/job_json.h"
#include "server/log.h"
#include "server/materials_catalog.h"
#include "server/problem.h"
#include "server/time_format.h"

namespace tessera::server {

using httplib::Request;
using httplib::Response;
using nlohmann::json;

namespace {

using Handler = std::function<void(const Request&, Response&)>;

struct Route {
  std::string method;
  std::string openapi_path;
  std::string pattern;  // cpp-httplib matches it against the whole path
  Handler handler;
};

constexpr const char* kJobId = "([^/]+)";  // checked by is_valid_job_id() before any use

void send_json(Response& res, int status, const json& body) {
  res.status = status;
  res.set_content(body.dump(-1, ' ', false, json::error_handler_t::replace), "application/json");
}

void send_problem(Response& res, const Problem& p) {
  res.status = p.status;
  res.set_content(p.to_json().dump(-1, ' ', false, json::error_handler_t::replace), kProblemMediaType);
}

void send_problem(Response& res, int status, const std::string& detail) {
  send_problem(res, Problem{status, detail, {}});
}

void job_not_found(Response& res) {
  send_problem(res, 404, "no such job");
}

// Streams a file from an open handle: a file renamed over meanwhile (a fresher preview) does not mix into it.
bool send_file(Response& res, const std::filesystem::path& path, const std::string& media_type) {
  auto in = std::make_shared<std::ifstream>(path, std::ios::binary);
  if (!*in) return false;
  in->seekg(0, std::ios::end);
  const auto size = static_cast<size_t>(in->tellg());
  in->seekg(0);
  res.status = 200;
  res.set_content_provider(size, media_type, [in](size_t offset, size_t length, httplib::DataSink& sink) {
    char buf[64 * 1024];
    in->seekg(static_cast<std::streamoff>(offset));
    in->read(buf, static_cast<std::streamsize>(std::min(length, sizeof buf)));
    const std::streamsize got = in->gcount();
    if (got <= 0) return false;
    return sink.write(buf, static_cast<size_t>(got));
  });
  return true;
}

// The job named by the first path capture, or an answered 404 (an id of the wrong shape is simply unknown).
std::optional<JobRecord> find_job(ApiContext& ctx, const Request& req, Response& res) {
  const std::string id = req.matches[1];
  if (!is_valid_job_id(id)) {
    job_not_found(res);
    return std::nullopt;
  }
  std::optional<JobRecord> job = ctx.store.get(id);
  if (!job) job_not_found(res);
  return job;
}

json status_of(ApiContext& ctx, const JobRecord& job) {
  return job_status_json(job, ctx.scheduler.live_progress(job.id));
}

void post_job(ApiContext& ctx, const Request& req, Response& res) {
  auto checked = check_submission(req.get_header_value("Content-Type"), req.body, ctx.limits);
  if (auto* problem = std::get_if<Problem>(&checked)) {
    log(LogLevel::kDebug, "job refused", {{"status", problem->status}, {"detail", problem->detail}});
    return send_problem(res, *problem);
  }
  if (!ctx.scheduler.accepting()) return send_problem(res, 503, "the daemon is shutting down");
  AcceptedJob& accepted = std::get<AcceptedJob>(checked);
  JobRecord job;
  job.id = new_job_id();
  job.kind = accepted.kind;
  job.priority = accepted.priority;
  job.created_at_ms = now_ms();
  job.document = accepted.document.dump();
  job.settings = accepted.settings.dump();
  job.outputs = accepted.outputs.dump();
  job.progress.samples_total = accepted.spp;
  ctx.store.create(job);
  ctx.scheduler.wake();
  log(LogLevel::kInfo, "job queued",
      {{"job", job.id}, {"kind", job.kind}, {"priority", job.priority}, {"render", accepted.settings}});
  res.set_header("Location", "/v1/jobs/" + job.id);
  send_json(res, 202, job_status_json(job));
}

void list_jobs(ApiContext& ctx, const Request& req, Response& res) {
  JobFilter filter;
  if (req.has_param("state")) {
    const std::string s = req.get_param_value("state");
    filter.state = parse_job_state(s);
    if (!filter.state)
      return send_problem(res, 400, "state must be queued, running, succeeded, failed or cancelled, not \"" + s + "\"");
  }
  if (req.has_param("limit")) {
    const std::string s = req.get_param_value("limit");
    int n = 0;
    auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), n);
    if (ec != std::errc() || end != s.data() + s.size() || n < 1 || n > 1000)
      return send_problem(res, 400, "limit must be an integer from 1 to 1000");
    filter.limit = n;
  }
  json jobs = json::array();
  for (const JobRecord& job : ctx.store.list(filter)) jobs.push_back(status_of(ctx, job));
  send_json(res, 200, {{"jobs", jobs}});
}

void get_preview(ApiContext& ctx, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  res.set_header("Cache-Control", "no-store");
  if (send_file(res, ctx.files.path(job->id, JobFile::kPreviewPng), "image/png")) return;
  if (!is_terminal(job->state))
    return send_problem(
        res, 409,
        std::string("the job is ") + job_state_name(job->state) + "; a preview exists after its first render pass");
  send_problem(res, 404, "this job has no preview (it ended before its first pass)");
}

void get_result(ApiContext& ctx, JobFile file, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  if (job->state != JobState::kSucceeded)
    return send_problem(
        res, 409, std::string("the job is ") + job_state_name(job->state) + "; results exist once it has succeeded");
  const std::string format = file == JobFile::kResultExr ? "exr" : "png";
  const json outputs = json::parse(job->outputs, nullptr, false);
  if (!outputs.is_array() || std::find(outputs.begin(), outputs.end(), format) == outputs.end())
    return send_problem(res, 404, "the job did not ask for a " + format + " output");
  if (!send_file(res, ctx.files.path(job->id, file), job_file_media_type(file)))
    send_problem(res, 404, std::string("the job's ") + job_file_name(file) + " is missing from the data directory");
}

void cancel_job(ApiContext& ctx, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  switch (ctx.scheduler.cancel(job->id)) {
    case Scheduler::CancelResult::kCancelled:
    case Scheduler::CancelResult::kCancelling: {
      auto now = ctx.store.get(job->id);
      if (!now) return job_not_found(res);
      // 202 while the render winds down (within one tile's time), 200 once the job is cancelled.
      return send_json(res, now->state == JobState::kCancelled ? 200 : 202, status_of(ctx, *now));
    }
    case Scheduler::CancelResult::kAlreadyFinished: {
      auto now = ctx.store.get(job->id);
      return send_problem(
          res, 409, std::string("the job has already ended: it is ") + job_state_name(now ? now->state : job->state));
    }
    case Scheduler::CancelResult::kUnknown:
      return job_not_found(res);
  }
}

std::vector<Route> routes(ApiContext* ctx) {
  const std::string job = std::string("/v1/jobs/") + kJobId;
  return {
      {"POST", "/v1/jobs", "/v1/jobs", [ctx](const Request& q, Response& r) { post_job(*ctx, q, r); }},
      {"GET", "/v1/jobs", "/v1/jobs", [ctx](const Request& q, Response& r) { list_jobs(*ctx, q, r); }},
      {"GET", "/v1/jobs/{id}", job,
       [ctx](const Request& q, Response& r) {
         if (auto j = find_job(*ctx, q, r)) send_json(r, 200, status_of(*ctx, *j));
       }},
      {"DELETE", "/v1/jobs/{id}", job,
       [ctx](const Request& q, Response& r) {
         const std::string id = q.matches[1];
         if (!is_valid_job_id(id) || !ctx->scheduler.remove(id)) return job_not_found(r);
         r.status = 204;
       }},
      {"POST", "/v1/jobs/{id}/cancel", job + "/cancel",
       [ctx](const Request& q, Response& r) { cancel_job(*ctx, q, r); }},
      {"GET", "/v1/jobs/{id}/preview.png", job + "/preview\\.png",
       [ctx](const Request& q, Response& r) { get_preview(*ctx, q, r); }},
      {"GET", "/v1/jobs/{id}/result.png", job + "/result\\.png",
       [ctx](const Request& q, Response& r) { get_result(*ctx, JobFile::kResultPng, q, r); }},
      {"GET", "/v1/jobs/{id}/result.exr", job + "/result\\.exr",
       [ctx](const Request& q, Response& r) { get_result(*ctx, JobFile::kResultExr, q, r); }},
      {"GET", "/v1/materials", "/v1/materials",
       [](const Request&, Response& r) {
         static const json catalog = describe_materials(contract_schemas());
         send_json(r, 200, catalog);
       }},
      {"GET", "/v1/schemas/{name}", "/v1/schemas/([^/]+)",
       [](const Request& q, Response& r) {
         // Looked up among the compiled-in files only: a name is never a filesystem path.
         const std::string name = q.matches[1];
         auto text = name.find('/') == std::string::npos ? contract_file("schemas/" + name) : std::nullopt;
         if (!text) return send_problem(r, 404, "no schema named \"" + name + "\"");
         r.set_content(std::string(*text), "application/schema+json");
       }},
      {"GET", "/v1/openapi.json", "/v1/openapi.json",
       [](const Request&, Response& r) { r.set_content(std::string(openapi_json()), "application/json"); }},
      {"GET", "/livez", "/livez",
       [](const Request&, Response& r) {
         send_json(r, 200, {{"status", "ok"}});
       }},
      {"GET", "/readyz", "/readyz",
       [ctx](const Request&, Response& r) {
         if (ctx->scheduler.accepting()) return send_json(r, 200, {{"status", "ready"}});
         send_problem(r, 503, "not accepting jobs (starting or shutting down)");
       }},
      {"GET", "/", "/",
       [](const Request&, Response& r) {
         auto page = web_file("index.html");
         if (!page) return send_problem(r, 404, "no web client in this build");
         r.set_content(std::string(*page), "text/html; charset=utf-8");
       }},
  };
}

// cpp-httplib answers some errors itself (no route: 404; body over the limit: 413; unreadable request: 400) with
// an empty body; they become problem+json here. A route that exists for another method is 405 with Allow.
httplib::Server::HandlerResponse on_error(const Request& req, Response& res) {
  if (!res.body.empty() || res.content_length_ > 0) return httplib::Server::HandlerResponse::Unhandled;
  if (res.status == 404) {
    std::string allow;
    for (const Route& r : routes(nullptr)) {
      if (r.method != req.method && std::regex_match(req.path, std::regex(r.pattern))) {
        if (allow.find(r.method) != std::string::npos) continue;
        allow += (allow.empty() ? "" : ", ") + r.method;
      }
    }
    if (!allow.empty()) {
      res.set_header("Allow", allow);
      send_problem(res, 405, req.method + " is not allowed on " + req.path + "; allowed: " + allow);
    } else {
      send_problem(res, 404, "no route for " + req.method + " " + req.path);
    }
  } else if (res.status == 413) {
    send_problem(res, 413, "the request body exceeds the configured limit (--max-body-bytes)");
  } else if (res.status == 414) {
    send_problem(res, 414, "the request URI is too long");
  } else {
    send_problem(res, res.status, "the request could not be handled");
  }
  return httplib::Server::HandlerResponse::Handled;
}

}  // namespace

std::vector<RouteInfo> api_routes() {
  std::vector<RouteInfo> out;
  for (const Route& r : routes(nullptr)) out.push_back({r.method, r.openapi_path});
  return out;
}

void install_api(httplib::Server& server, ApiContext& ctx) {
  auto posts = std::make_shared<std::vector<std::pair<std::regex, Handler>>>();
  for (Route& r : routes(&ctx)) {
    if (r.method == "GET")
      server.Get(r.pattern, r.handler);
    else if (r.method == "POST")
      server.Post(r.pattern, r.handler);
    else if (r.method == "DELETE")
      server.Delete(r.pattern, r.handler);
    if (r.method == "POST") posts->emplace_back(std::regex(r.pattern), r.handler);
  }
  // A request with neither Content-Length nor Transfer-Encoding has an empty body (RFC 9112, 6.3), but
  // cpp-httplib 0.11 answers such a POST (`curl -X POST .../cancel`) with 400. Those are routed here instead.
  server.set_pre_routing_handler([posts](const Request& req, Response& res) {
    if (req.method != "POST" || req.has_header("Content-Length") || req.has_header("Transfer-Encoding"))
      return httplib::Server::HandlerResponse::Unhandled;
    for (const auto& [pattern, handler] : *posts) {
      // The request object is not const inside cpp-httplib; its routing fills `matches` the same way.
      if (std::regex_match(req.path, const_cast<Request&>(req).matches, pattern)) {
        handler(req, res);
        return httplib::Server::HandlerResponse::Handled;
      }
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });
  server.set_payload_max_length(ctx.max_body_bytes);
  server.set_error_handler(httplib::Server::HandlerWithResponse(on_error));
  server.set_exception_handler([](const Request& req, Response& res, std::exception_ptr ep) {
    std::string what = "unknown exception";
    try {
      if (ep) std::rethrow_exception(ep);
    } catch (const std::exception& e) {
      what = e.what();
    } catch (...) {
    }
    log(LogLevel::kError, "request failed", {{"method", req.method}, {"path", req.path}, {"error", what}});
    res.headers.clear();
    send_problem(res, 500, "internal error; the daemon's log has the details");
  });
  server.set_logger([](const Request& req, const Response& res) {
    log(LogLevel::kDebug, "request", {{"method", req.method}, {"path", req.path}, {"status", res.status}});
  });
}

}  // namespace tessera::server
