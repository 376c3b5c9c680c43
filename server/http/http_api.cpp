#include "server/http/http_api.h"

#include <httplib.h>
#include <sys/stat.h>

#include <algorithm>
#include <charconv>
#include <fstream>
#include <functional>
#include <regex>
#include <set>

#include "proto/contract.h"
#include "renderer/scene_error.h"
#include "server/base/job_id.h"
#include "server/base/log.h"
#include "server/base/problem.h"
#include "server/base/time_format.h"
#include "server/http/http_transport.h"
#include "server/http/request_body.h"
#include "server/http/web_files.h"
#include "server/jobs/job_json.h"
#include "server/jobs/materials_catalog.h"

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
constexpr const char* kWebFile =
    "/([A-Za-z0-9_-][A-Za-z0-9._-]{0,127}\\.(?:js|mjs|css|html|svg|png|ico|json|map|webmanifest))";

void send_json(Response& res, int status, const json& body) {
  res.status = status;
  res.set_content(body.dump(-1, ' ', false, json::error_handler_t::replace), "application/json");
}

void send_problem(Response& res, const Problem& p) {
  if (p.retry_after_s) res.set_header("Retry-After", std::to_string(*p.retry_after_s));
  res.status = p.status;
  res.set_content(p.to_json().dump(-1, ' ', false, json::error_handler_t::replace), kProblemMediaType);
}

void send_problem(Response& res, int status, const std::string& detail) {
  send_problem(res, Problem{status, detail, {}});
}

void job_not_found(Response& res) {
  send_problem(res, 404, "no such job");
}

// Seconds a client waits before retrying a request the job store failed (JobStoreError, answered by the exception
// handler): a database locked past its busy timeout or an I/O error passes within seconds or needs an operator, and
// a retry costs the daemon little either way. Space, once full, is freed by someone (a client deleting jobs, the
// --retain-finished sweep): a slower retry.
constexpr const char* kStoreRetryAfterS = "5";
constexpr const char* kStoreFullRetryAfterS = "30";

// ---- storage -------------------------------------------------------------------------------------------------

// Bytes available to the daemon (not to root) on the data directory's filesystem; nothing when it cannot be asked.
std::optional<uint64_t> available_bytes(const ApiContext& ctx) {
  std::error_code ec;
  const std::filesystem::space_info space = std::filesystem::space(ctx.data_dir, ec);
  if (ec) return std::nullopt;
  return static_cast<uint64_t>(space.available);
}

// Answers 507 and returns true when the data directory's filesystem has less than --min-free-disk available: called
// before a request writes anything. A filesystem that cannot be asked does not refuse (the writes report their own
// errors).
bool refused_for_storage(const ApiContext& ctx, Response& res) {
  if (ctx.min_free_disk_bytes == 0) return false;
  const std::optional<uint64_t> available = available_bytes(ctx);
  if (!available) {
    log(LogLevel::kWarn, "cannot read the free space of the data directory", {{"data_dir", ctx.data_dir.string()}});
    return false;
  }
  if (*available >= ctx.min_free_disk_bytes) return false;
  log(LogLevel::kWarn, "request refused: the data directory's disk is nearly full",
      {{"available_bytes", *available}, {"min_free_disk_bytes", ctx.min_free_disk_bytes}});
  send_problem(res, insufficient_storage("the data directory has " + std::to_string(*available) +
                                         " bytes available, less than --min-free-disk (" +
                                         std::to_string(ctx.min_free_disk_bytes) + " bytes)"));
  return true;
}

bool etag_matches(const std::string& if_none_match, const std::string& etag) {
  if (if_none_match.empty()) return false;
  if (if_none_match == "*") return true;
  std::string list = if_none_match;
  size_t at = 0;
  while (at < list.size()) {
    size_t comma = list.find(',', at);
    std::string t = list.substr(at, comma == std::string::npos ? std::string::npos : comma - at);
    t.erase(0, t.find_first_not_of(" \t"));
    t.erase(t.find_last_not_of(" \t") + 1);
    if (t.rfind("W/", 0) == 0) t = t.substr(2);
    if (t == etag) return true;
    if (comma == std::string::npos) break;
    at = comma + 1;
  }
  return false;
}

// Streams one version of a file (a fresher preview written meanwhile does not mix into it), with its ETag; a matching
// If-None-Match is answered 304.
void send_file(const Request& req, Response& res, std::shared_ptr<FileReader> file, const std::string& media_type) {
  res.set_header("ETag", file->etag());
  if (etag_matches(req.get_header_value("If-None-Match"), file->etag())) {
    res.status = 304;
    return;
  }
  res.status = 200;
  res.set_content_provider(file->size(), media_type, [file](size_t offset, size_t length, httplib::DataSink& sink) {
    char buf[64 * 1024];
    const size_t got = file->read(offset, buf, std::min(length, sizeof buf));
    return got > 0 && sink.write(buf, got);
  });
}

// A file the job service gave, or its problem.
void send_file_or_problem(const Request& req, Response& res, std::variant<std::unique_ptr<FileReader>, Problem> file,
                          const std::string& media_type) {
  if (auto* p = std::get_if<Problem>(&file)) return send_problem(res, *p);
  send_file(req, res, std::move(std::get<std::unique_ptr<FileReader>>(file)), media_type);
}

// The job store as /readyz and /metrics both report it: failing while the end of a render waits for the store to
// take it (a full disk, a database locked or failing), or when the store cannot be read now; the job counts when it
// can.
struct StoreHealth {
  std::optional<std::map<JobState, int>> counts;
  bool failing = false;
};

StoreHealth store_health(ApiContext& ctx) {
  StoreHealth h;
  try {
    h.counts = ctx.jobs.counts();
  } catch (const JobStoreError& e) {
    ctx.metrics.count_job_store_error();
    log(LogLevel::kWarn, "the job store cannot be read", {{"error", e.what()}});
  }
  h.failing = !h.counts || ctx.jobs.store_failing();
  return h;
}

bool is_event_stream_path(std::string_view path) {
  return path == "/v1/events" || (path.size() > 7 && path.compare(path.size() - 7, 7, "/events") == 0);
}

Caller caller_of(ApiContext& ctx, const Request& req) {
  // EventSource cannot send headers: event streams also take ?access_token=.
  const std::string query_token =
      is_event_stream_path(req.path) && req.has_param("access_token") ? req.get_param_value("access_token") : "";
  return ctx.auth.identify(req.get_header_value("Authorization"), query_token);
}

// The job named by the first path capture and visible to the caller, or an answered 404 (an id of the wrong shape,
// or another user's job, is simply unknown).
std::optional<JobRecord> find_job(ApiContext& ctx, const Request& req, Response& res) {
  std::optional<JobRecord> job = ctx.jobs.find(caller_of(ctx, req), req.matches[1]);
  if (!job) job_not_found(res);
  return job;
}

// Retry-After while a job has not ended: how long a poller should wait (the event stream needs no polling).
void set_retry_after(Response& res, const JobRecord& job) {
  if (job.state == JobState::kQueued) res.set_header("Retry-After", "2");
  if (job.state == JobState::kRunning) res.set_header("Retry-After", "1");
}

// ---- jobs ----------------------------------------------------------------------------------------------------

struct Submission {
  nlohmann::json document;
  std::string request_hash;  // what an Idempotency-Key is compared by
};

bool valid_idempotency_key(const std::string& k) {
  return !k.empty() && k.size() <= 255 &&
         std::all_of(k.begin(), k.end(), [](unsigned char c) { return c > 32 && c < 127; });
}

// The bytes of a request's body or of one of its parts, moved out of the request: an upload is held once, not copied
// again for the asset store. The request object is not const inside cpp-httplib (read_body filled it), and nothing
// reads the bytes after the handler that takes them.
std::string take_bytes(const std::string& bytes) {
  return std::move(const_cast<std::string&>(bytes));
}

// A multipart submission: the part "job" plus files, which the job service stores as assets (the job's names for
// them become their ids).
std::variant<Submission, Problem> multipart_submission(ApiContext& ctx, const Request& req, const Caller& caller) {
  if (!req.has_file("job"))
    return Problem{422, "a multipart job needs a part named \"job\" holding the job document (JSON)", std::nullopt};
  const std::string job_text = req.get_file_value("job").content;
  auto parsed = parse_document(job_text, ctx.limits.max_depth);
  if (auto* problem = std::get_if<Problem>(&parsed)) return *problem;
  json doc = std::move(std::get<json>(parsed));
  std::vector<UploadFile> files;
  for (const auto& [name, part] : req.files) {
    if (name == "job") continue;
    if (part.filename.empty()) return Problem{422, "the part \"" + name + "\" is not a file", std::nullopt};
    files.push_back({part.filename, take_bytes(part.content)});
  }
  std::string manifest = job_text + "\n";
  {
    std::vector<std::string> lines;
    for (const UploadFile& f : files) lines.push_back(f.name + "\t" + sha256_hex(f.bytes));
    std::sort(lines.begin(), lines.end());
    for (const std::string& l : lines) manifest += l + "\n";
  }
  if (auto problem = ctx.jobs.store_uploads(caller, doc, std::move(files))) return *problem;
  return Submission{std::move(doc), sha256_hex(manifest)};
}

void post_job(ApiContext& ctx, const Request& req, Response& res) {
  // Before anything is stored: a multipart submission writes its files as assets first.
  if (refused_for_storage(ctx, res)) return;
  const Caller caller = caller_of(ctx, req);
  const std::string key = req.get_header_value("Idempotency-Key");
  if (req.has_header("Idempotency-Key") && !valid_idempotency_key(key))
    return send_problem(res, 400, "Idempotency-Key must be 1 to 255 visible ASCII characters");

  // A user's job may name only the user's own assets.
  SubmissionLimits limits = ctx.limits;
  if (!caller.admin) limits.resolve_asset = asset_resolver(ctx.assets, caller.name);
  std::variant<AcceptedJob, Problem> checked;
  std::string request_hash;
  const bool multipart = media_type(req.get_header_value("Content-Type")) == "multipart/form-data";
  if (multipart) {
    auto sub = multipart_submission(ctx, req, caller);
    if (auto* p = std::get_if<Problem>(&sub)) return send_problem(res, *p);
    request_hash = std::get<Submission>(sub).request_hash;
    checked = check_job_document(std::move(std::get<Submission>(sub).document), limits);
  } else {
    checked = check_submission(req.get_header_value("Content-Type"), req.body, limits);
    request_hash = sha256_hex(req.body);
  }
  if (auto* problem = std::get_if<Problem>(&checked)) {
    log(LogLevel::kDebug, "job refused", {{"status", problem->status}, {"detail", problem->detail}});
    return send_problem(res, *problem);
  }
  auto submitted =
      ctx.jobs.submit(caller, SubmitRequest{std::move(std::get<AcceptedJob>(checked)), key, request_hash, multipart});
  if (auto* p = std::get_if<Problem>(&submitted)) return send_problem(res, *p);
  const Submitted& s = std::get<Submitted>(submitted);
  res.set_header("Location", "/v1/jobs/" + s.job.id);
  if (s.created) {
    res.set_header("Retry-After", "1");
    return send_json(res, 202, s.status);
  }
  set_retry_after(res, s.job);
  send_json(res, 200, s.status);
}

void list_jobs(ApiContext& ctx, const Request& req, Response& res) {
  const Caller caller = caller_of(ctx, req);
  JobFilter filter;
  if (req.has_param("state")) {
    const std::string all = req.get_param_value("state");
    size_t at = 0;
    while (at <= all.size()) {
      size_t comma = all.find(',', at);
      const std::string s = all.substr(at, comma == std::string::npos ? std::string::npos : comma - at);
      auto state = parse_job_state(s);
      if (!state) {
        std::string names;
        for (JobState st : kAllJobStates) names += std::string(names.empty() ? "" : ", ") + job_state_name(st);
        return send_problem(res, 400,
                            "state must be a comma-separated list of " + names + "; not \"" + s.substr(0, 64) + "\"");
      }
      filter.states.push_back(*state);
      if (comma == std::string::npos) break;
      at = comma + 1;
    }
  }
  if (req.has_param("limit")) {
    const std::string s = req.get_param_value("limit");
    int n = 0;
    auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), n);
    if (ec != std::errc() || end != s.data() + s.size() || n < 1 || n > 1000)
      return send_problem(res, 400, "limit must be an integer from 1 to 1000");
    filter.limit = n;
  }
  if (req.has_param("cursor")) {
    // Opaque to clients: "s" and the hex submission number of the last job of the previous page.
    const std::string c = req.get_param_value("cursor");
    int64_t seq = 0;
    bool ok = c.size() >= 2 && c.size() <= 17 && c[0] == 's';
    if (ok) {
      auto [end, ec] = std::from_chars(c.data() + 1, c.data() + c.size(), seq, 16);
      ok = ec == std::errc() && end == c.data() + c.size() && seq > 0;
    }
    if (!ok) return send_problem(res, 400, "cursor is not one this server gave out (next_cursor of a listing)");
    filter.before_seq = seq;
  }
  const JobPage page = ctx.jobs.list(caller, filter);
  json next = nullptr;
  if (page.next_before_seq) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "s%llx", static_cast<unsigned long long>(*page.next_before_seq));
    next = buf;
  }
  send_json(res, 200, {{"jobs", page.jobs}, {"next_cursor", next}});
}

void get_preview(ApiContext& ctx, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  res.set_header("Cache-Control", "no-cache");
  send_file_or_problem(req, res, ctx.jobs.preview(*job), "image/png");
}

void get_result(ApiContext& ctx, JobFile file, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  send_file_or_problem(req, res, ctx.jobs.result(*job, file), job_file_media_type(file));
}

// A render pass of a finished job as PNG (render.aovs): a look at it; its numbers are in result.exr.
void get_pass(ApiContext& ctx, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  send_file_or_problem(req, res, ctx.jobs.pass(*job, req.matches[2].str()), "image/png");
}

// A frame of a frame range job: its output, or one of its render passes as PNG.
void get_frame_result(ApiContext& ctx, JobFile file, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  send_file_or_problem(req, res, ctx.jobs.frame_result(*job, req.matches[2].str(), file), job_file_media_type(file));
}

void get_frame_pass(ApiContext& ctx, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  send_file_or_problem(req, res,
                       ctx.jobs.frame_result(*job, req.matches[2].str(), JobFile::kResultPng, req.matches[3].str()),
                       "image/png");
}

// The document the job was accepted with, as JSON: what a client needs to submit it again.
void get_document(ApiContext& ctx, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  auto document = ctx.jobs.document(*job);
  if (!document) return job_not_found(res);  // deleted meanwhile
  res.status = 200;
  res.set_content(std::move(*document), "application/json");
}

// The job's log as text; empty before it has one (a job that has not started rendering).
void get_log(ApiContext& ctx, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  res.set_header("Cache-Control", "no-cache");
  const char* type = job_file_media_type(JobFile::kLog);
  if (auto file = ctx.jobs.job_log(*job)) return send_file(req, res, std::move(file), type);
  res.status = 200;
  res.set_content("", type);
}

// A job after an action: 200 with its status, the change recorded.
void send_taken(Response& res, const std::variant<ActionTaken, Problem>& taken) {
  if (auto* p = std::get_if<Problem>(&taken)) return send_problem(res, *p);
  const ActionTaken& t = std::get<ActionTaken>(taken);
  set_retry_after(res, t.job);
  send_json(res, 200, t.status);
}

void job_action(ApiContext& ctx, const Request& req, Response& res, JobAction action) {
  if (auto job = find_job(ctx, req, res)) send_taken(res, ctx.jobs.act(*job, action));
}

void patch_job(ApiContext& ctx, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  const std::string type = media_type(req.get_header_value("Content-Type"));
  if (type != "application/json" && type != "application/merge-patch+json")
    return send_problem(res, 415, "a job is patched with application/json or application/merge-patch+json");
  auto parsed = parse_document(req.body, ctx.limits.max_depth);
  if (auto* problem = std::get_if<Problem>(&parsed)) return send_problem(res, *problem);
  const json body = std::move(std::get<json>(parsed));
  if (!body.is_object()) return send_problem(res, Problem{422, "must be an object like {\"priority\": 10}", ""});
  for (const auto& [k, v] : body.items())
    if (k != "priority")
      return send_problem(res, Problem{422, "only \"priority\" can be changed", "/" + json_pointer_token(k)});
  if (!body.contains("priority")) return send_problem(res, Problem{422, "\"priority\" is required", "/priority"});
  const json& p = body["priority"];
  if (!p.is_number_integer() || p.get<int64_t>() < -100 || p.get<int64_t>() > 100)
    return send_problem(res, Problem{422, "must be an integer from -100 to 100", "/priority"});
  send_taken(res, ctx.jobs.set_priority(caller_of(ctx, req), *job, p.get<int>()));
}

// ---- Server-Sent Events --------------------------------------------------------------------------------------

std::string sse_event(uint64_t id, const std::string& type, const std::string& data) {
  return "id: " + std::to_string(id) + "\nevent: " + type + "\ndata: " + data + "\n\n";
}

std::optional<uint64_t> last_event_id(const Request& req) {
  std::string v = req.get_header_value("Last-Event-ID");
  if (v.empty() && req.has_param("last_event_id")) v = req.get_param_value("last_event_id");
  uint64_t n = 0;
  auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), n);
  if (v.empty() || ec != std::errc() || end != v.data() + v.size()) return std::nullopt;
  return n;
}

struct StreamState {
  uint64_t after = 0;
  bool started = false;
  std::optional<uint64_t> resume_from;
};

void stream_events(ApiContext& ctx, const Request& req, Response& res, const std::optional<JobRecord>& job) {
  const Caller caller = caller_of(ctx, req);
  const std::string job_id = job ? job->id : "";
  auto state = std::make_shared<StreamState>();
  state->resume_from = last_event_id(req);
  res.status = 200;
  res.set_header("Cache-Control", "no-cache");
  res.set_header("X-Accel-Buffering", "no");  // proxies (nginx) must not buffer the stream
  ApiContext* c = &ctx;
  res.set_chunked_content_provider("text/event-stream", [c, state, job_id, caller](size_t, httplib::DataSink& sink) {
    // The answer's status is sent by now: a store that fails from here on cannot be answered 503, and nothing
    // catches around a content provider of cpp-httplib (the exception would end the daemon). The stream ends
    // instead; EventSource reconnects (with Last-Event-ID) and gets the 503 until the store recovers.
    try {
      // The current state of the job as an event whose id is the stream's newest: a reconnect with it as
      // Last-Event-ID continues right after.
      auto snapshot = [&]() -> bool {
        auto now = c->jobs.find(caller, job_id);
        if (!now) {
          sink.done();
          return true;
        }
        state->after = c->events.last_seq(job_id);
        const std::string event = sse_event(state->after, "state", c->jobs.status(*now).dump());
        if (!sink.write(event.data(), event.size())) return false;
        if (is_terminal(now->state)) sink.done();
        return true;
      };
      auto write = [&](const std::string& s) { return sink.write(s.data(), s.size()); };
      if (!state->started) {
        state->started = true;
        if (!write(": connected\n\n")) return false;
        if (!state->resume_from) {
          if (job_id.empty()) {
            state->after = c->events.last_seq("");
            return true;
          }
          return snapshot();
        }
        state->after = *state->resume_from;
        EventRead r = c->events.wait(job_id, state->after, 0);
        if (!job_id.empty() && (r.gap || (r.events.empty() && r.last_seq < state->after))) return snapshot();
      }
      EventRead r = c->events.wait(job_id, state->after, c->keepalive_s * 1000);
      if (r.closed) {
        sink.done();
        return true;
      }
      if (r.events.empty()) {
        if (!job_id.empty() && !c->jobs.find(caller, job_id)) {  // deleted meanwhile
          sink.done();
          return true;
        }
        return write(": keep-alive\n\n");
      }
      for (const JobEvent& e : r.events) {
        state->after = e.seq;
        if (!caller.admin && e.owner != caller.name) continue;
        if (!write(sse_event(e.seq, e.type, e.data))) return false;
        if (!job_id.empty() && e.terminal) {
          sink.done();
          return true;
        }
      }
      return true;
    } catch (const JobStoreError& e) {
      c->metrics.count_job_store_error();
      log(LogLevel::kWarn, "event stream ended: the job store failed", {{"job", job_id}, {"error", e.what()}});
      return false;
    } catch (const std::exception& e) {
      log(LogLevel::kError, "event stream failed", {{"job", job_id}, {"error", e.what()}});
      return false;
    }
  });
}

// ---- assets --------------------------------------------------------------------------------------------------

// The asset named by the first path capture and visible to the caller (an uploader of it, or an admin).
std::optional<AssetInfo> find_asset(ApiContext& ctx, const Request& req) {
  auto info = ctx.assets.get(req.matches[1]);
  const Caller caller = caller_of(ctx, req);
  if (info && !caller.admin && !info->owned_by(caller.name)) return std::nullopt;
  return info;
}

void post_asset(ApiContext& ctx, const Request& req, Response& res) {
  if (refused_for_storage(ctx, res)) return;
  const Caller caller = caller_of(ctx, req);
  const std::string type = media_type(req.get_header_value("Content-Type"));
  std::vector<UploadFile> files;
  if (type == "multipart/form-data") {
    for (const auto& [name, part] : req.files) {
      if (part.filename.empty()) return send_problem(res, 422, "the part \"" + name + "\" is not a file");
      files.push_back({part.filename, take_bytes(part.content)});
    }
  } else {
    static const std::map<std::string, std::pair<std::string, std::vector<std::string>>> kTypes = {
        {"model/gltf-binary", {"asset.glb", {".glb"}}},
        {"model/gltf+json", {"asset.gltf", {".gltf"}}},
        {"image/vnd.radiance", {"map.hdr", {".hdr"}}},
        {"image/x-exr", {"map.exr", {".exr"}}},
        {"image/aces", {"map.exr", {".exr"}}},
        {"application/octet-stream", {"", {".glb", ".gltf", ".hdr", ".exr", ".vdb"}}},
    };
    auto it = kTypes.find(type);
    if (it == kTypes.end()) {
      // The types the table takes, those without a default name saying that they need one.
      std::string accepted;
      for (const auto& [accepted_type, name_and_extensions] : kTypes)
        accepted += ", " + accepted_type + (name_and_extensions.first.empty() ? " (with ?name=file.ext)" : "");
      return send_problem(res, 415,
                          "an asset is multipart/form-data or one file of type " + accepted.substr(2) + ", not \"" +
                              req.get_header_value("Content-Type").substr(0, 100) + "\"");
    }
    std::string name = req.has_param("name") ? req.get_param_value("name") : it->second.first;
    if (name.empty()) return send_problem(res, 422, "an application/octet-stream upload needs ?name=file.ext");
    std::string ext = std::filesystem::path(name).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return std::tolower(ch); });
    const auto& allowed = it->second.second;
    if (std::find(allowed.begin(), allowed.end(), ext) == allowed.end())
      return send_problem(res, 422, "the name \"" + name.substr(0, 128) + "\" does not fit the content type " + type);
    files.push_back({name, take_bytes(req.body)});
  }
  auto stored = ctx.assets.store(std::move(files), caller.name);
  if (auto* p = std::get_if<Problem>(&stored)) {
    // A disk that filled up is the operator's concern; a bad upload is the client's.
    log(p->status == 507 ? LogLevel::kWarn : LogLevel::kInfo, "asset refused",
        {{"status", p->status}, {"detail", p->detail}});
    return send_problem(res, *p);
  }
  const StoredAsset& s = std::get<StoredAsset>(stored);
  if (s.created)
    log(LogLevel::kInfo, "asset stored", {{"asset", s.info.id}, {"kind", s.info.kind}, {"bytes", s.info.bytes}});
  res.set_header("Location", "/v1/assets/" + s.info.id);
  send_json(res, s.created ? 201 : 200, s.info.to_json());
}

// ---- routes --------------------------------------------------------------------------------------------------

std::vector<Route> routes(ApiContext* ctx) {
  const std::string job = std::string("/v1/jobs/") + kJobId;
  const std::string asset = "/v1/assets/([^/]+)";
  auto action = [ctx](JobAction a) { return [=](const Request& q, Response& r) { job_action(*ctx, q, r, a); }; };
  return {
      {"POST", "/v1/jobs", "/v1/jobs", [ctx](const Request& q, Response& r) { post_job(*ctx, q, r); }},
      {"GET", "/v1/jobs", "/v1/jobs", [ctx](const Request& q, Response& r) { list_jobs(*ctx, q, r); }},
      {"GET", "/v1/jobs/{id}", job,
       [ctx](const Request& q, Response& r) {
         if (auto j = find_job(*ctx, q, r)) {
           set_retry_after(r, *j);
           send_json(r, 200, ctx->jobs.status(*j));
         }
       }},
      {"PATCH", "/v1/jobs/{id}", job, [ctx](const Request& q, Response& r) { patch_job(*ctx, q, r); }},
      {"DELETE", "/v1/jobs/{id}", job,
       [ctx](const Request& q, Response& r) {
         auto j = find_job(*ctx, q, r);
         if (!j) return;
         if (!ctx->jobs.remove(j->id)) return job_not_found(r);
         r.status = 204;
       }},
      {"POST", "/v1/jobs/{id}/cancel", job + "/cancel", action(JobAction::kCancel)},
      {"POST", "/v1/jobs/{id}/pause", job + "/pause", action(JobAction::kPause)},
      {"POST", "/v1/jobs/{id}/resume", job + "/resume", action(JobAction::kResume)},
      {"POST", "/v1/jobs/{id}/requeue", job + "/requeue", action(JobAction::kRequeue)},
      {"GET", "/v1/jobs/{id}/events", job + "/events",
       [ctx](const Request& q, Response& r) {
         if (auto j = find_job(*ctx, q, r)) stream_events(*ctx, q, r, j);
       }},
      {"GET", "/v1/jobs/{id}/document", job + "/document",
       [ctx](const Request& q, Response& r) { get_document(*ctx, q, r); }},
      {"GET", "/v1/jobs/{id}/log", job + "/log", [ctx](const Request& q, Response& r) { get_log(*ctx, q, r); }},
      {"GET", "/v1/jobs/{id}/preview.png", job + "/preview\\.png",
       [ctx](const Request& q, Response& r) { get_preview(*ctx, q, r); }},
      {"GET", "/v1/jobs/{id}/result.png", job + "/result\\.png",
       [ctx](const Request& q, Response& r) { get_result(*ctx, JobFile::kResultPng, q, r); }},
      {"GET", "/v1/jobs/{id}/result.exr", job + "/result\\.exr",
       [ctx](const Request& q, Response& r) { get_result(*ctx, JobFile::kResultExr, q, r); }},
      {"GET", "/v1/jobs/{id}/aovs/{name}.png", job + "/aovs/([^/]{1,64})\\.png",
       [ctx](const Request& q, Response& r) { get_pass(*ctx, q, r); }},
      {"GET", "/v1/jobs/{id}/frames/{frame}/result.png", job + "/frames/([^/]{1,32})/result\\.png",
       [ctx](const Request& q, Response& r) { get_frame_result(*ctx, JobFile::kResultPng, q, r); }},
      {"GET", "/v1/jobs/{id}/frames/{frame}/result.exr", job + "/frames/([^/]{1,32})/result\\.exr",
       [ctx](const Request& q, Response& r) { get_frame_result(*ctx, JobFile::kResultExr, q, r); }},
      {"GET", "/v1/jobs/{id}/frames/{frame}/aovs/{name}.png", job + "/frames/([^/]{1,32})/aovs/([^/]{1,64})\\.png",
       [ctx](const Request& q, Response& r) { get_frame_pass(*ctx, q, r); }},
      {"GET", "/v1/events", "/v1/events",
       [ctx](const Request& q, Response& r) { stream_events(*ctx, q, r, std::nullopt); }},
      {"POST", "/v1/assets", "/v1/assets", [ctx](const Request& q, Response& r) { post_asset(*ctx, q, r); }},
      {"GET", "/v1/assets/{id}", asset,
       [ctx](const Request& q, Response& r) {
         auto info = find_asset(*ctx, q);
         if (!info) return send_problem(r, 404, "no such asset");
         send_json(r, 200, info->to_json());
       }},
      {"DELETE", "/v1/assets/{id}", asset,
       [ctx](const Request& q, Response& r) {
         auto info = find_asset(*ctx, q);
         if (!info) return send_problem(r, 404, "no such asset");
         // A user gives up their own claim (the files go with the last one); an admin removes the asset.
         const Caller caller = caller_of(*ctx, q);
         if (!ctx->assets.remove(info->id, caller.admin ? std::nullopt : std::optional(caller.name)))
           return send_problem(r, 404, "no such asset");
         log(LogLevel::kInfo, "asset deleted", {{"asset", info->id}});
         r.status = 204;
       }},
      {"GET", "/v1/materials", "/v1/materials",
       [](const Request&, Response& r) {
         static const json catalog = describe_materials(proto::contract_schemas());
         send_json(r, 200, catalog);
       }},
      {"GET", "/v1/schemas/{name}", "/v1/schemas/([^/]+)",
       [](const Request& q, Response& r) {
         // Looked up among the compiled-in files only: a name is never a filesystem path.
         const std::string name = q.matches[1];
         auto text = name.find('/') == std::string::npos ? proto::contract_file("schemas/" + name) : std::nullopt;
         if (!text) return send_problem(r, 404, "no schema named \"" + name.substr(0, 128) + "\"");
         r.set_content(std::string(*text), "application/schema+json");
       }},
      {"GET", "/v1/openapi.json", "/v1/openapi.json",
       [](const Request&, Response& r) { r.set_content(std::string(proto::openapi_json()), "application/json"); }},
      {"GET", "/metrics", "/metrics",
       [ctx](const Request&, Response& r) {
         Metrics::Gauges g;
         // A failing store costs the scrape its job counts, not the scrape: the rest is what an operator needs then.
         const StoreHealth health = store_health(*ctx);
         g.jobs = health.counts;
         g.job_store_up = !health.failing;
         g.render_threads = ctx->pool ? ctx->pool->size() : 0;
         g.render_threads_busy = ctx->pool ? ctx->pool->busy() : 0;
         g.event_watchers = ctx->events.watchers();
         if (ctx->store_notifications_up) g.store_notifications_up = ctx->store_notifications_up();
         if (ctx->transport) {
           const TransportStats t = ctx->transport->stats();
           g.http_connections = t.connections;
           g.http_refused_total = t.refused_total;
           g.http_timed_out_total = t.timed_out_total;
         }
         g.data_dir_available_bytes = available_bytes(*ctx);
         g.min_free_disk_bytes = ctx->min_free_disk_bytes;
         r.set_content(ctx->metrics.render(g), "text/plain; version=0.0.4; charset=utf-8");
       }},
      {"GET", "/livez", "/livez",
       [](const Request&, Response& r) {
         send_json(r, 200, {{"status", "ok"}});
       }},
      {"GET", "/readyz", "/readyz",
       [ctx](const Request&, Response& r) {
         // Ready with a nearly full disk, and with a job store that fails to record the end of a job, too: reads,
         // cancels and deletes go on (a store that fails is usually a full disk), and taking the one daemon that
         // holds these jobs out of a load balancer would cut them off. Both are reported, for alerts.
         const std::optional<uint64_t> available = available_bytes(*ctx);
         json storage = {{"available_bytes", available ? json(*available) : json(nullptr)},
                         {"min_free_disk_bytes", ctx->min_free_disk_bytes},
                         {"below_minimum", available && *available < ctx->min_free_disk_bytes},
                         {"job_store_failing", store_health(*ctx).failing}};
         if (ctx->jobs.accepting()) return send_json(r, 200, {{"status", "ready"}, {"storage", storage}});
         send_problem(r, 503, "not accepting jobs (starting or shutting down)");
       }},
      {"GET", "/", "/",
       [](const Request&, Response& r) {
         auto page = web_file("index.html");
         if (!page) return send_problem(r, 404, "no web client in this build");
         r.set_content(std::string(*page), "text/html; charset=utf-8");
       }},
      {"GET", "/{file}", kWebFile,
       [](const Request& q, Response& r) {
         // The web client's other files (scripts, styles), compiled in: a name is never a filesystem path.
         const std::string name = q.matches[1];
         auto file = web_file(name);
         if (!file) return send_problem(r, 404, "no web client file named \"" + name + "\"");
         r.set_content(std::string(*file), web_media_type(name));
       }},
  };
}

struct CompiledRoute {
  std::string method, openapi_path;
  std::regex pattern;
};

const std::vector<CompiledRoute>& compiled_routes() {
  static const std::vector<CompiledRoute> list = [] {
    std::vector<CompiledRoute> out;
    for (const Route& r : routes(nullptr)) out.push_back({r.method, r.openapi_path, std::regex(r.pattern)});
    return out;
  }();
  return list;
}

// The OpenAPI path of the route whose handler runs on this thread for the current request; null before routing and
// when no handler ran (no route, 405, 401, OPTIONS).
thread_local const std::string* t_routed = nullptr;

// The route pattern a request matched (for metrics labels: never the path itself). A handler's route is known without
// matching the path against every route again.
std::string route_label(const Request& req) {
  if (t_routed) return *t_routed;
  std::string other;
  for (const CompiledRoute& r : compiled_routes()) {
    if (!std::regex_match(req.path, r.pattern)) continue;
    if (r.method == req.method) return r.openapi_path;
    other = r.openapi_path;
  }
  return other.empty() ? "unmatched" : other;
}

// Paths anyone may fetch, tokens or not: health, metrics, the web client.
bool is_public(const Request& req) {
  if (req.path == "/livez" || req.path == "/readyz" || req.path == "/metrics") return true;
  static const std::regex web(kWebFile);
  return req.method == "GET" && (req.path == "/" || std::regex_match(req.path, web));
}

// cpp-httplib answers some errors itself (no route: 404; body over the limit: 413; unreadable request: 400) with
// an empty body; they become problem+json here. A route that exists for another method is 405 with Allow.
httplib::Server::HandlerResponse on_error(const Request& req, Response& res) {
  if (!res.body.empty() || res.content_length_ > 0 || res.status == 304)
    return httplib::Server::HandlerResponse::Unhandled;
  if (res.status == 404) {
    std::string allow;
    for (const CompiledRoute& r : compiled_routes()) {
      if (r.method != req.method && std::regex_match(req.path, r.pattern)) {
        if (allow.find(r.method) != std::string::npos) continue;
        allow += (allow.empty() ? "" : ", ") + r.method;
      }
    }
    if (!allow.empty()) {
      res.set_header("Allow", allow);
      send_problem(res, 405, req.method + " is not allowed on " + req.path.substr(0, 200) + "; allowed: " + allow);
    } else {
      send_problem(res, 404, "no route for " + req.method.substr(0, 16) + " " + req.path.substr(0, 200));
    }
  } else if (res.status == 413) {
    send_problem(res, 413, "the request body exceeds the configured limit (--max-body-bytes)");
  } else if (res.status == 414) {
    send_problem(res, 414, "the request URI is too long");
  } else if (res.status >= 400) {
    send_problem(res, res.status, "the request could not be handled");
  } else {
    return httplib::Server::HandlerResponse::Unhandled;
  }
  return httplib::Server::HandlerResponse::Handled;
}

}  // namespace

std::vector<RouteInfo> api_routes() {
  std::vector<RouteInfo> out;
  for (const Route& r : routes(nullptr)) out.push_back({r.method, r.openapi_path});
  return out;
}

bool is_event_stream_target(std::string_view target) {
  return is_event_stream_path(target.substr(0, target.find('?')));
}

void install_api(httplib::Server& server, ApiContext& ctx) {
  auto posts = std::make_shared<std::vector<std::pair<std::regex, Handler>>>();
  ApiContext* c = &ctx;
  // Routes that take a body read it as it arrives, decoded, within --max-body-bytes (a chunked or compressed body
  // too); cpp-httplib's own reading would hold all of it, inflated, before any limit applied.
  const auto with_body = [c](Handler handler) {
    return [c, handler = std::move(handler)](const Request& q, Response& s, const httplib::ContentReader& read) {
      // The request object is not const inside cpp-httplib, which fills req.body and req.files the same way.
      if (auto problem = read_body(const_cast<Request&>(q), read, c->max_body_bytes)) {
        HttpTransport::close_after_response();
        return send_problem(s, *problem);
      }
      handler(q, s);
    };
  };
  for (Route& r : routes(&ctx)) {
    // cpp-httplib dispatches to the first route of the method whose pattern matches, as route_label() would find.
    r.handler = [handler = std::move(r.handler), label = r.openapi_path](const Request& q, Response& s) {
      t_routed = &label;
      handler(q, s);
    };
    if (r.method == "GET")
      server.Get(r.pattern, r.handler);
    else if (r.method == "POST")
      server.Post(r.pattern, with_body(r.handler));
    else if (r.method == "PATCH")
      server.Patch(r.pattern, with_body(r.handler));
    else if (r.method == "DELETE")
      server.Delete(r.pattern, with_body(r.handler));
    if (r.method == "POST") posts->emplace_back(std::regex(r.pattern), r.handler);
  }
  // A body sent to no route is not read (on_error answers 404 or 405) and its connection closes after the answer.
  const auto unrouted = [](const Request&, Response& s, const httplib::ContentReader&) {
    HttpTransport::close_after_response();
    s.status = 404;
  };
  server.Post(".*", unrouted).Put(".*", unrouted).Patch(".*", unrouted).Delete(".*", unrouted);

  // Expect: 100-continue is answered with the refusal instead when the head already decides one (RFC 9110, 10.1.1).
  server.set_expect_100_continue_handler([c](const Request& req, Response& res) {
    auto problem = check_request_head(req, c->max_body_bytes);
    if (!problem) return 100;
    HttpTransport::close_after_response();
    send_problem(res, *problem);
    // cpp-httplib writes this answer as it is, without the length it adds to others.
    res.set_header("Content-Length", std::to_string(res.body.size()));
    return problem->status;
  });
  server.set_pre_routing_handler([posts, c](const Request& req, Response& res) {
    t_routed = nullptr;
    // An answer given here leaves the body unread: the connection closes after it.
    const auto handled = [&req] {
      if (has_body(req)) HttpTransport::close_after_response();
      return httplib::Server::HandlerResponse::Handled;
    };
    if (body_left_unread(req)) HttpTransport::close_after_response();
    // CORS: only for the configured origins.
    const std::string origin = req.get_header_value("Origin");
    const bool cors_ok = !origin.empty() && std::any_of(c->cors_origins.begin(), c->cors_origins.end(),
                                                        [&](const std::string& o) { return o == origin || o == "*"; });
    if (cors_ok) {
      res.set_header("Access-Control-Allow-Origin", origin);
      res.set_header("Vary", "Origin");
      res.set_header("Access-Control-Expose-Headers", "Location, ETag, Retry-After, Allow");
    }
    if (auto problem = check_request_head(req, c->max_body_bytes)) {
      if (problem->status == 415) res.set_header("Accept-Encoding", "gzip, deflate, br");
      send_problem(res, *problem);
      HttpTransport::close_after_response();
      return httplib::Server::HandlerResponse::Handled;
    }
    if (req.method == "OPTIONS") {
      if (!cors_ok) {
        send_problem(res, 403,
                     "cross-origin requests from \"" + origin.substr(0, 200) + "\" are not allowed (--cors-origin)");
        return handled();
      }
      res.set_header("Access-Control-Allow-Methods", "GET, POST, PATCH, DELETE, OPTIONS");
      res.set_header("Access-Control-Allow-Headers",
                     "Authorization, Content-Type, Idempotency-Key, If-None-Match, Last-Event-ID");
      res.set_header("Access-Control-Max-Age", "600");
      res.status = 204;
      return handled();
    }
    if (c->auth.enabled() && !is_public(req) && !caller_of(*c, req).authenticated) {
      res.set_header("WWW-Authenticate", "Bearer realm=\"tessera\"");
      send_problem(res, 401, "a valid bearer token is required (Authorization: Bearer <token>)");
      return handled();
    }
    // A request with neither Content-Length nor Transfer-Encoding has an empty body (RFC 9112, 6.3), but
    // cpp-httplib 0.11 answers such a POST (`curl -X POST .../cancel`) with 400. Those are routed here instead.
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
  server.set_payload_max_length(ctx.max_body_bytes);  // what the routes read is bounded above; this is a backstop
  // Without TCP_NODELAY, a keep-alive client waits for the delayed ACK between the header and body writes: ~25 ms
  // a request (150 status requests/s on 4 connections, measured); with it, the latency is the work.
  server.set_tcp_nodelay(true);
  // cpp-httplib closes a keep-alive connection after 5 requests by default: a poller then reconnects every 5th
  // request (accept, a pool thread's wake-up, close, on both sides). An idle connection still closes after 5 s.
  server.set_keep_alive_max_count(1000);
  server.set_error_handler(httplib::Server::HandlerWithResponse(on_error));
  server.set_exception_handler([c](const Request& req, Response& res, std::exception_ptr ep) {
    std::string what = "unknown exception";
    std::optional<bool> store_full;  // the job store failed; whether it ran out of space
    try {
      if (ep) std::rethrow_exception(ep);
    } catch (const JobStoreError& e) {
      what = e.what();
      store_full = e.out_of_space();
    } catch (const std::exception& e) {
      what = e.what();
    } catch (...) {
    }
    // What the handler set before it threw (Location, ETag, a job's Retry-After) belonged to an answer not given. The
    // CORS headers stay: a browser client must be able to read this answer, and its Retry-After.
    for (auto it = res.headers.begin(); it != res.headers.end();)
      it = it->first.rfind("Access-Control-", 0) == 0 || it->first == "Vary" ? std::next(it) : res.headers.erase(it);
    if (store_full) {
      c->metrics.count_job_store_error();
      // The store, not the request or the daemon, is at fault, and it usually recovers (a lock released, space
      // freed): the client is told to retry. The operator's alert is tessera_http_requests_total{code="503"|"507"}.
      log(LogLevel::kWarn, "request failed: the job store failed",
          {{"method", req.method}, {"path", req.path}, {"error", what}, {"out_of_space", *store_full}});
      if (*store_full) {
        // Only a write runs out of space; each is one SQLite statement, rolled back whole, and no route changes
        // anything (files, renders) before its write: nothing of the request took effect.
        res.set_header("Retry-After", kStoreFullRetryAfterS);
        return send_problem(res, insufficient_storage("the job store ran out of space (the data directory's disk or "
                                                      "quota is full)",
                                                      "nothing was changed"));
      }
      res.set_header("Retry-After", kStoreRetryAfterS);
      return send_problem(res, 503,
                          "the job store is failing for now (a database locked too long, an I/O error); the request "
                          "can be retried in a few seconds");
    }
    log(LogLevel::kError, "request failed", {{"method", req.method}, {"path", req.path}, {"error", what}});
    send_problem(res, 500, "internal error; the daemon's log has the details");
  });
  // Counted before the response is written (the logger runs after it), so that a client that has its answer also
  // finds it in /metrics.
  server.set_post_routing_handler(
      [c](const Request& req, Response& res) { c->metrics.count_request(route_label(req), res.status); });
  // The last step of every request (the pre-routing handler resets it too).
  server.set_logger([c](const Request& req, const Response& res) {
    if (log_enabled(LogLevel::kDebug)) {
      const std::string route = route_label(req);
      // The path, never the query: an access_token may be in it.
      log(LogLevel::kDebug, "request",
          {{"method", req.method}, {"path", req.path}, {"route", route}, {"status", res.status}});
    }
    t_routed = nullptr;
  });
}

}  // namespace tessera::server
