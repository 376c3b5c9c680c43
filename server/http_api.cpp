#include "server/http_api.h"

#include <httplib.h>
#include <sys/stat.h>

#include <algorithm>
#include <charconv>
#include <fstream>
#include <functional>
#include <regex>
#include <set>

#include "renderer/scene_error.h"
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
constexpr const char* kWebFile = "/([A-Za-z0-9_-][A-Za-z0-9._-]{0,127}\\.(?:js|mjs|css|html|svg|png|ico|json|map|webmanifest))";

std::string web_media_type(const std::string& name) {
  static const std::map<std::string, std::string> types = {
      {"js", "text/javascript; charset=utf-8"}, {"mjs", "text/javascript; charset=utf-8"},
      {"css", "text/css; charset=utf-8"},       {"html", "text/html; charset=utf-8"},
      {"svg", "image/svg+xml"},                 {"png", "image/png"},
      {"ico", "image/x-icon"},                  {"json", "application/json"},
      {"map", "application/json"},              {"webmanifest", "application/manifest+json"}};
  auto it = types.find(name.substr(name.rfind('.') + 1));
  return it == types.end() ? "application/octet-stream" : it->second;
}

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

// The identity of a file's current version: a preview renamed over gets a new one.
std::optional<std::string> file_etag(const std::filesystem::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return std::nullopt;
  char buf[96];
  std::snprintf(buf, sizeof buf, "\"%llx-%llx-%llx\"", static_cast<unsigned long long>(st.st_ino),
                static_cast<unsigned long long>(st.st_size),
                static_cast<unsigned long long>(st.st_mtim.tv_sec) * 1000000000ull +
                    static_cast<unsigned long long>(st.st_mtim.tv_nsec));
  return std::string(buf);
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

// Streams a file from an open handle: a file renamed over meanwhile (a fresher preview) does not mix into it.
// With an ETag; a matching If-None-Match is answered 304.
bool send_file(const Request& req, Response& res, const std::filesystem::path& path, const std::string& media_type) {
  const auto etag = file_etag(path);
  auto in = std::make_shared<std::ifstream>(path, std::ios::binary);
  if (!*in || !etag) return false;
  res.set_header("ETag", *etag);
  if (etag_matches(req.get_header_value("If-None-Match"), *etag)) {
    res.status = 304;
    return true;
  }
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

bool is_event_stream_path(const std::string& path) {
  return path == "/v1/events" || (path.size() > 7 && path.compare(path.size() - 7, 7, "/events") == 0);
}

Caller caller_of(ApiContext& ctx, const Request& req) {
  // EventSource cannot send headers: event streams also take ?access_token=.
  const std::string query_token =
      is_event_stream_path(req.path) && req.has_param("access_token") ? req.get_param_value("access_token") : "";
  return ctx.auth.identify(req.get_header_value("Authorization"), query_token);
}

bool may_see(const Caller& caller, const JobRecord& job) {
  return caller.admin || job.owner == caller.name;
}

// The job named by the first path capture and visible to the caller, or an answered 404 (an id of the wrong shape,
// or another user's job, is simply unknown).
std::optional<JobRecord> find_job(ApiContext& ctx, const Request& req, Response& res) {
  const std::string id = req.matches[1];
  if (!is_valid_job_id(id)) {
    job_not_found(res);
    return std::nullopt;
  }
  std::optional<JobRecord> job = ctx.store.get(id);
  if (!job || !may_see(caller_of(ctx, req), *job)) {
    job_not_found(res);
    return std::nullopt;
  }
  return job;
}

json status_of(ApiContext& ctx, const JobRecord& job) {
  std::optional<int> position;
  if (job.state == JobState::kQueued) position = ctx.store.queue_position(job.id);
  return job_status_json(job, ctx.scheduler.live_progress(job.id), position);
}

// Retry-After while a job has not ended: how long a poller should wait (the event stream needs no polling).
void set_retry_after(Response& res, const JobRecord& job) {
  if (job.state == JobState::kQueued) res.set_header("Retry-After", "2");
  if (job.state == JobState::kRunning) res.set_header("Retry-After", "1");
}

void publish_state(ApiContext& ctx, const std::string& id) {
  auto job = ctx.store.get(id);
  if (!job) return;
  ctx.events.publish(id, job->owner, "state", status_of(ctx, *job).dump(), is_terminal(job->state));
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

// A multipart submission: the part "job" plus files. Files the job names (scene.gltf, scene.environment.map) are
// stored as assets first and the names replaced by the asset ids.
std::variant<Submission, Problem> multipart_submission(ApiContext& ctx, const Request& req, const Caller& caller) {
  if (!req.has_file("job"))
    return Problem{422, "a multipart job needs a part named \"job\" holding the job document (JSON)", std::nullopt};
  const std::string job_text = req.get_file_value("job").content;
  if (json_nesting_depth(job_text) > static_cast<size_t>(ctx.limits.max_depth))
    return Problem{422, "the document is nested deeper than " + std::to_string(ctx.limits.max_depth) + " levels", ""};
  json doc = json::parse(job_text, nullptr, false);
  if (doc.is_discarded()) return Problem{400, "the part \"job\" is not valid JSON", ""};
  std::vector<UploadFile> files;
  for (const auto& [name, part] : req.files) {
    if (name == "job") continue;
    if (part.filename.empty()) return Problem{422, "the part \"" + name + "\" is not a file", std::nullopt};
    files.push_back({part.filename, part.content});
  }
  std::string manifest = job_text + "\n";
  {
    std::vector<std::string> lines;
    for (const UploadFile& f : files) lines.push_back(f.name + "\t" + sha256_hex(f.bytes));
    std::sort(lines.begin(), lines.end());
    for (const std::string& l : lines) manifest += l + "\n";
  }
  if (!files.empty() && doc.is_object() && doc.contains("scene") && doc["scene"].is_object()) {
    json& scene = doc["scene"];
    // The map the job names becomes an environment asset of its own; the rest is the glTF asset.
    if (scene.contains("environment") && scene["environment"].is_object() &&
        scene["environment"].contains("map") && scene["environment"]["map"].is_string()) {
      const std::string map = scene["environment"]["map"];
      auto it = std::find_if(files.begin(), files.end(), [&](const UploadFile& f) { return f.name == map; });
      if (it != files.end()) {
        std::vector<UploadFile> one{*it};
        files.erase(it);
        auto stored = ctx.assets.store(std::move(one), caller.name);
        if (auto* p = std::get_if<Problem>(&stored)) return *p;
        scene["environment"]["map"] = std::get<StoredAsset>(stored).info.id;
      }
    }
    if (!files.empty()) {
      const bool named = scene.contains("gltf") && scene["gltf"].is_string() &&
                         std::any_of(files.begin(), files.end(),
                                     [&](const UploadFile& f) { return f.name == scene["gltf"].get<std::string>(); });
      auto stored = ctx.assets.store(std::move(files), caller.name);
      if (auto* p = std::get_if<Problem>(&stored)) return *p;
      const AssetInfo& info = std::get<StoredAsset>(stored).info;
      if (named && info.kind == "gltf") scene["gltf"] = info.id;
    }
  } else if (!files.empty()) {
    return Problem{422, "uploaded files need a scene job that names them", "/scene"};
  }
  return Submission{std::move(doc), sha256_hex(manifest)};
}

void post_job(ApiContext& ctx, const Request& req, Response& res) {
  // Before anything is stored: a multipart submission writes its files as assets first.
  if (refused_for_storage(ctx, res)) return;
  const Caller caller = caller_of(ctx, req);
  const std::string key = req.get_header_value("Idempotency-Key");
  if (req.has_header("Idempotency-Key") && !valid_idempotency_key(key))
    return send_problem(res, 400, "Idempotency-Key must be 1 to 255 visible ASCII characters");

  std::variant<AcceptedJob, Problem> checked;
  std::string request_hash;
  const bool multipart = media_type(req.get_header_value("Content-Type")) == "multipart/form-data";
  if (multipart) {
    auto sub = multipart_submission(ctx, req, caller);
    if (auto* p = std::get_if<Problem>(&sub)) return send_problem(res, *p);
    request_hash = std::get<Submission>(sub).request_hash;
    checked = check_job_document(std::move(std::get<Submission>(sub).document), ctx.limits);
  } else {
    checked = check_submission(req.get_header_value("Content-Type"), req.body, ctx.limits);
    request_hash = sha256_hex(req.body);
  }
  if (auto* problem = std::get_if<Problem>(&checked)) {
    log(LogLevel::kDebug, "job refused", {{"status", problem->status}, {"detail", problem->detail}});
    return send_problem(res, *problem);
  }
  if (!ctx.scheduler.accepting()) return send_problem(res, 503, "the daemon is shutting down");

  auto answer_existing = [&](const JobRecord& existing) {
    if (existing.request_hash != request_hash)
      return send_problem(res, 422, "this Idempotency-Key was used with another request body");
    res.set_header("Location", "/v1/jobs/" + existing.id);
    set_retry_after(res, existing);
    send_json(res, 200, status_of(ctx, existing));
  };
  if (!key.empty())
    if (auto existing = ctx.store.find_by_idempotency_key(caller.name, key)) return answer_existing(*existing);

  AcceptedJob& accepted = std::get<AcceptedJob>(checked);
  if (accepted.priority > ctx.max_user_priority && !caller.admin)
    return send_problem(res, Problem{403,
                                     "priority " + std::to_string(accepted.priority) + " is above " +
                                         std::to_string(ctx.max_user_priority) + ", which needs an admin token",
                                     "/priority"});
  if (ctx.max_queued_per_user > 0) {
    const auto counts = ctx.store.count_by_state(caller.name);
    if (counts.at(JobState::kQueued) >= ctx.max_queued_per_user) {
      res.set_header("Retry-After", "30");
      return send_problem(res, 429,
                          "you have " + std::to_string(counts.at(JobState::kQueued)) +
                              " jobs queued, the most this server allows (--max-queued-per-user); retry later");
    }
  }
  JobRecord job;
  job.id = new_job_id();
  job.kind = accepted.kind;
  job.priority = accepted.priority;
  job.created_at_ms = now_ms();
  job.document = accepted.document.dump();
  job.settings = accepted.settings.dump();
  job.outputs = accepted.outputs.dump();
  job.progress.samples_total = accepted.spp;
  job.owner = caller.name;
  job.warnings = json(accepted.warnings).dump();
  job.idempotency_key = key;
  job.request_hash = request_hash;
  try {
    ctx.store.create(job);
  } catch (const std::exception& e) {
    // The same key raced in from another connection: that request's job is this one's.
    if (!key.empty())
      if (auto existing = ctx.store.find_by_idempotency_key(caller.name, key)) return answer_existing(*existing);
    // The disk filled after the --min-free-disk check: the insert was rolled back whole, so, as the check's refusal,
    // nothing of the job exists (assets a multipart submission stored stay: whole, and found again by a retry).
    if (const auto* se = dynamic_cast<const JobStoreError*>(&e); se && se->out_of_space()) {
      ctx.metrics.count_job_store_error();
      log(LogLevel::kWarn, "job refused: the job store ran out of space", {{"error", e.what()}});
      const std::string kept = multipart ? "the job was not stored; the files uploaded with it were, whole, and a "
                                           "retry reuses them"
                                         : "nothing was stored";
      return send_problem(
          res, insufficient_storage("the data directory's disk ran out of space while the job was stored", kept));
    }
    throw;
  }
  ctx.scheduler.wake();
  log(LogLevel::kInfo, "job queued",
      {{"job", job.id}, {"kind", job.kind}, {"priority", job.priority}, {"owner", job.owner},
       {"render", accepted.settings}});
  // The job exists from here on: a store that fails as it is read back costs the answer its queue position (and the
  // event its watchers), not a 503 whose retry, without an Idempotency-Key, would queue the job twice.
  json status;
  try {
    publish_state(ctx, job.id);
    auto stored = ctx.store.get(job.id);
    status = status_of(ctx, stored ? *stored : job);
  } catch (const JobStoreError& e) {
    ctx.metrics.count_job_store_error();
    log(LogLevel::kWarn, "job queued, but the job store failed as it was read back",
        {{"job", job.id}, {"error", e.what()}});
    status = job_status_json(job);
  }
  res.set_header("Location", "/v1/jobs/" + job.id);
  res.set_header("Retry-After", "1");
  send_json(res, 202, status);
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
      if (!state)
        return send_problem(res, 400,
                            "state must be a comma-separated list of queued, running, paused, succeeded, failed, "
                            "cancelled; not \"" + s.substr(0, 64) + "\"");
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
  if (!caller.admin) filter.owner = caller.name;
  const int limit = filter.limit;
  filter.limit = limit + 1;  // one more tells whether another page exists
  std::vector<JobRecord> jobs = ctx.store.list(filter);
  json next = nullptr;
  if (static_cast<int>(jobs.size()) > limit) {
    jobs.resize(static_cast<size_t>(limit));
    char buf[32];
    std::snprintf(buf, sizeof buf, "s%llx", static_cast<unsigned long long>(jobs.back().seq));
    next = buf;
  }
  json out = json::array();
  for (const JobRecord& job : jobs) out.push_back(status_of(ctx, job));
  send_json(res, 200, {{"jobs", out}, {"next_cursor", next}});
}

void get_preview(ApiContext& ctx, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  res.set_header("Cache-Control", "no-cache");
  if (send_file(req, res, ctx.files.path(job->id, JobFile::kPreviewPng), "image/png")) return;
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
  if (!send_file(req, res, ctx.files.path(job->id, file), job_file_media_type(file)))
    send_problem(res, 404, std::string("the job's ") + job_file_name(file) + " is missing from the data directory");
}

using Action = Scheduler::Outcome (Scheduler::*)(const std::string&);

void job_action(ApiContext& ctx, const Request& req, Response& res, Action action, const char* verb,
                const char* allowed_from) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  switch ((ctx.scheduler.*action)(job->id)) {
    case Scheduler::Outcome::kDone:
    case Scheduler::Outcome::kInProgress: {
      auto now = ctx.store.get(job->id);
      if (!now) return job_not_found(res);
      // 202 while a running render winds down (within one pass), 200 once the state has changed.
      const bool changed = now->state != JobState::kRunning;
      set_retry_after(res, *now);
      return send_json(res, changed ? 200 : 202, status_of(ctx, *now));
    }
    case Scheduler::Outcome::kConflict: {
      auto now = ctx.store.get(job->id);
      return send_problem(res, 409,
                          std::string("cannot ") + verb + " a job that is " +
                              job_state_name(now ? now->state : job->state) + "; only a job that is " + allowed_from);
    }
    case Scheduler::Outcome::kUnknown:
      return job_not_found(res);
  }
}

void patch_job(ApiContext& ctx, const Request& req, Response& res) {
  auto job = find_job(ctx, req, res);
  if (!job) return;
  const std::string type = media_type(req.get_header_value("Content-Type"));
  if (type != "application/json" && type != "application/merge-patch+json")
    return send_problem(res, 415, "a job is patched with application/json or application/merge-patch+json");
  json body = json::parse(req.body, nullptr, false);
  if (body.is_discarded()) return send_problem(res, Problem{400, "the body is not valid JSON", ""});
  if (!body.is_object()) return send_problem(res, Problem{422, "must be an object like {\"priority\": 10}", ""});
  for (const auto& [k, v] : body.items())
    if (k != "priority")
      return send_problem(res, Problem{422, "only \"priority\" can be changed", "/" + json_pointer_token(k)});
  if (!body.contains("priority")) return send_problem(res, Problem{422, "\"priority\" is required", "/priority"});
  const json& p = body["priority"];
  if (!p.is_number_integer() || p.get<int64_t>() < -100 || p.get<int64_t>() > 100)
    return send_problem(res, Problem{422, "must be an integer from -100 to 100", "/priority"});
  const int priority = p.get<int>();
  const Caller caller = caller_of(ctx, req);
  if (priority > ctx.max_user_priority && !caller.admin)
    return send_problem(res, Problem{403,
                                     "priority " + std::to_string(priority) + " is above " +
                                         std::to_string(ctx.max_user_priority) + ", which needs an admin token",
                                     "/priority"});
  if (!ctx.store.set_priority(job->id, priority))
    return send_problem(res, 409,
                        std::string("the job has ended (") + job_state_name(job->state) + "); its priority is final");
  log(LogLevel::kInfo, "job priority changed", {{"job", job->id}, {"priority", priority}});
  publish_state(ctx, job->id);
  auto now = ctx.store.get(job->id);
  if (!now) return job_not_found(res);
  send_json(res, 200, status_of(ctx, *now));
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
  res.set_chunked_content_provider(
      "text/event-stream", [c, state, job_id, caller](size_t, httplib::DataSink& sink) {
        // The answer's status is sent by now: a store that fails from here on cannot be answered 503, and nothing
        // catches around a content provider of cpp-httplib (the exception would end the daemon). The stream ends
        // instead; EventSource reconnects (with Last-Event-ID) and gets the 503 until the store recovers.
        try {
          // The current state of the job as an event whose id is the stream's newest: a reconnect with it as
          // Last-Event-ID continues right after.
          auto snapshot = [&]() -> bool {
            auto now = c->store.get(job_id);
            if (!now) {
              sink.done();
              return true;
            }
            state->after = c->events.last_seq(job_id);
            const std::string event = sse_event(state->after, "state", status_of(*c, *now).dump());
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
            if (!job_id.empty() && !c->store.get(job_id)) {  // deleted meanwhile
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

void post_asset(ApiContext& ctx, const Request& req, Response& res) {
  if (refused_for_storage(ctx, res)) return;
  const Caller caller = caller_of(ctx, req);
  const std::string type = media_type(req.get_header_value("Content-Type"));
  std::vector<UploadFile> files;
  if (type == "multipart/form-data") {
    for (const auto& [name, part] : req.files) {
      if (part.filename.empty()) return send_problem(res, 422, "the part \"" + name + "\" is not a file");
      files.push_back({part.filename, part.content});
    }
  } else {
    static const std::map<std::string, std::pair<std::string, std::vector<std::string>>> kTypes = {
        {"model/gltf-binary", {"asset.glb", {".glb"}}},
        {"model/gltf+json", {"asset.gltf", {".gltf"}}},
        {"image/vnd.radiance", {"map.hdr", {".hdr"}}},
        {"image/x-exr", {"map.exr", {".exr"}}},
        {"image/aces", {"map.exr", {".exr"}}},
        {"application/octet-stream", {"", {".glb", ".gltf", ".hdr", ".exr"}}},
    };
    auto it = kTypes.find(type);
    if (it == kTypes.end())
      return send_problem(res, 415,
                          "an asset is model/gltf-binary, model/gltf+json, image/vnd.radiance, image/x-exr or "
                          "multipart/form-data, not \"" + req.get_header_value("Content-Type").substr(0, 100) + "\"");
    std::string name = req.has_param("name") ? req.get_param_value("name") : it->second.first;
    if (name.empty()) return send_problem(res, 422, "an application/octet-stream upload needs ?name=file.ext");
    std::string ext = std::filesystem::path(name).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return std::tolower(ch); });
    const auto& allowed = it->second.second;
    if (std::find(allowed.begin(), allowed.end(), ext) == allowed.end())
      return send_problem(res, 422, "the name \"" + name.substr(0, 128) + "\" does not fit the content type " + type);
    files.push_back({name, req.body});
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
  auto action = [ctx](Action a, const char* verb, const char* from) {
    return [=](const Request& q, Response& r) { job_action(*ctx, q, r, a, verb, from); };
  };
  return {
      {"POST", "/v1/jobs", "/v1/jobs", [ctx](const Request& q, Response& r) { post_job(*ctx, q, r); }},
      {"GET", "/v1/jobs", "/v1/jobs", [ctx](const Request& q, Response& r) { list_jobs(*ctx, q, r); }},
      {"GET", "/v1/jobs/{id}", job,
       [ctx](const Request& q, Response& r) {
         if (auto j = find_job(*ctx, q, r)) {
           set_retry_after(r, *j);
           send_json(r, 200, status_of(*ctx, *j));
         }
       }},
      {"PATCH", "/v1/jobs/{id}", job, [ctx](const Request& q, Response& r) { patch_job(*ctx, q, r); }},
      {"DELETE", "/v1/jobs/{id}", job,
       [ctx](const Request& q, Response& r) {
         auto j = find_job(*ctx, q, r);
         if (!j) return;
         if (!remove_job(*ctx, j->id)) return job_not_found(r);
         r.status = 204;
       }},
      {"POST", "/v1/jobs/{id}/cancel", job + "/cancel",
       action(&Scheduler::cancel, "cancel", "queued, running or paused can be cancelled")},
      {"POST", "/v1/jobs/{id}/pause", job + "/pause",
       action(&Scheduler::pause, "pause", "queued or running can be paused")},
      {"POST", "/v1/jobs/{id}/resume", job + "/resume",
       action(&Scheduler::resume, "resume", "paused can be resumed")},
      {"POST", "/v1/jobs/{id}/requeue", job + "/requeue",
       action(&Scheduler::requeue, "requeue", "failed or cancelled can be requeued")},
      {"GET", "/v1/jobs/{id}/events", job + "/events",
       [ctx](const Request& q, Response& r) {
         if (auto j = find_job(*ctx, q, r)) stream_events(*ctx, q, r, j);
       }},
      {"GET", "/v1/jobs/{id}/preview.png", job + "/preview\\.png",
       [ctx](const Request& q, Response& r) { get_preview(*ctx, q, r); }},
      {"GET", "/v1/jobs/{id}/result.png", job + "/result\\.png",
       [ctx](const Request& q, Response& r) { get_result(*ctx, JobFile::kResultPng, q, r); }},
      {"GET", "/v1/jobs/{id}/result.exr", job + "/result\\.exr",
       [ctx](const Request& q, Response& r) { get_result(*ctx, JobFile::kResultExr, q, r); }},
      {"GET", "/v1/events", "/v1/events",
       [ctx](const Request& q, Response& r) { stream_events(*ctx, q, r, std::nullopt); }},
      {"POST", "/v1/assets", "/v1/assets", [ctx](const Request& q, Response& r) { post_asset(*ctx, q, r); }},
      {"GET", "/v1/assets/{id}", asset,
       [ctx](const Request& q, Response& r) {
         auto info = ctx->assets.get(q.matches[1]);
         if (!info) return send_problem(r, 404, "no such asset");
         send_json(r, 200, info->to_json());
       }},
      {"DELETE", "/v1/assets/{id}", asset,
       [ctx](const Request& q, Response& r) {
         auto info = ctx->assets.get(q.matches[1]);
         if (!info) return send_problem(r, 404, "no such asset");
         const Caller caller = caller_of(*ctx, q);
         if (!caller.admin && info->owner != caller.name)
           return send_problem(r, 403, "only the uploader or an admin may delete an asset");
         if (!ctx->assets.remove(info->id)) return send_problem(r, 404, "no such asset");
         log(LogLevel::kInfo, "asset deleted", {{"asset", info->id}});
         r.status = 204;
       }},
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
         if (!text) return send_problem(r, 404, "no schema named \"" + name.substr(0, 128) + "\"");
         r.set_content(std::string(*text), "application/schema+json");
       }},
      {"GET", "/v1/openapi.json", "/v1/openapi.json",
       [](const Request&, Response& r) { r.set_content(std::string(openapi_json()), "application/json"); }},
      {"GET", "/metrics", "/metrics",
       [ctx](const Request&, Response& r) {
         Metrics::Gauges g;
         // A failing store costs the scrape its job counts, not the scrape: the rest is what an operator needs then.
         try {
           g.jobs = ctx->store.count_by_state();
         } catch (const JobStoreError& e) {
           g.job_store_up = false;
           ctx->metrics.count_job_store_error();
           log(LogLevel::kWarn, "metrics without job counts: the job store failed", {{"error", e.what()}});
         }
         g.render_threads = ctx->pool ? ctx->pool->size() : 0;
         g.render_threads_busy = ctx->pool ? ctx->pool->busy() : 0;
         g.event_watchers = ctx->events.watchers();
         g.data_dir_available_bytes = available_bytes(*ctx);
         g.min_free_disk_bytes = ctx->min_free_disk_bytes;
         r.set_content(ctx->metrics.render(g), "text/plain; version=0.0.4; charset=utf-8");
       }},
      {"GET", "/livez", "/livez", [](const Request&, Response& r) { send_json(r, 200, {{"status", "ok"}}); }},
      {"GET", "/readyz", "/readyz",
       [ctx](const Request&, Response& r) {
         // Ready with a nearly full disk, and with a job store that fails to record the end of a job, too: reads,
         // cancels and deletes go on (a store that fails is usually a full disk), and taking the one daemon that
         // holds these jobs out of a load balancer would cut them off. Both are reported, for alerts.
         const std::optional<uint64_t> available = available_bytes(*ctx);
         json storage = {{"available_bytes", available ? json(*available) : json(nullptr)},
                         {"min_free_disk_bytes", ctx->min_free_disk_bytes},
                         {"below_minimum", available && *available < ctx->min_free_disk_bytes},
                         {"job_store_failing", ctx->scheduler.store_failing()}};
         if (ctx->scheduler.accepting()) return send_json(r, 200, {{"status", "ready"}, {"storage", storage}});
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

bool remove_job(ApiContext& ctx, const std::string& id, std::optional<int64_t> only_finished_before_ms) {
  if (!ctx.scheduler.remove(id, only_finished_before_ms)) return false;
  ctx.events.forget(id);
  return true;
}

std::function<std::filesystem::path(const std::string&, const std::string&)> asset_resolver(const AssetStore& assets) {
  return [&assets](const std::string& ref, const std::string& pointer) -> std::filesystem::path {
    const bool map = pointer.size() >= 4 && pointer.compare(pointer.size() - 4, 4, "/map") == 0;
    const std::string kind = map ? "environment" : "gltf";
    if (!is_asset_id(ref))
      throw SceneError(pointer, "must be an asset id (64 hex digits) from POST /v1/assets");
    auto path = assets.main_file(ref, kind);
    if (!path) {
      auto info = assets.get(ref);
      throw SceneError(pointer, info ? "asset " + ref + " is a " + info->kind + " asset, not a " + kind + " asset"
                                     : "no asset " + ref + " (upload it with POST /v1/assets)");
    }
    return *path;
  };
}

void install_api(httplib::Server& server, ApiContext& ctx) {
  auto posts = std::make_shared<std::vector<std::pair<std::regex, Handler>>>();
  for (Route& r : routes(&ctx)) {
    // cpp-httplib dispatches to the first route of the method whose pattern matches, as route_label() would find.
    r.handler = [handler = std::move(r.handler), label = r.openapi_path](const Request& q, Response& s) {
      t_routed = &label;
      handler(q, s);
    };
    if (r.method == "GET")
      server.Get(r.pattern, r.handler);
    else if (r.method == "POST")
      server.Post(r.pattern, r.handler);
    else if (r.method == "PATCH")
      server.Patch(r.pattern, r.handler);
    else if (r.method == "DELETE")
      server.Delete(r.pattern, r.handler);
    if (r.method == "POST") posts->emplace_back(std::regex(r.pattern), r.handler);
  }

  SchedulerHooks hooks;
  ApiContext* c = &ctx;
  hooks.state_changed = [c](const std::string& id) { publish_state(*c, id); };
  hooks.progress = [c](const std::string& id, const JobProgress& p) {
    auto job = c->store.get(id);
    if (!job) return;
    json status = job_status_json(*job, p);
    c->events.publish(id, job->owner, "progress", json{{"id", id}, {"progress", status["progress"]}}.dump());
  };
  hooks.preview = [c](const std::string& id, uint32_t pass) {
    auto job = c->store.get(id);
    if (!job) return;
    c->events.publish(id, job->owner, "preview",
                      json{{"id", id},
                           {"pass", pass},
                           {"url", "/v1/jobs/" + id + "/preview.png?pass=" + std::to_string(pass)}}
                          .dump());
  };
  hooks.samples_rendered = [c](uint64_t n) { c->metrics.add_samples(n); };
  hooks.job_ended = [c](double s) { c->metrics.observe_job_duration(s); };
  hooks.store_write_failed = [c] { c->metrics.count_job_store_error(); };
  ctx.scheduler.set_hooks(std::move(hooks));

  server.set_pre_routing_handler([posts, c](const Request& req, Response& res) {
    t_routed = nullptr;
    // CORS: only for the configured origins.
    const std::string origin = req.get_header_value("Origin");
    const bool cors_ok =
        !origin.empty() && std::any_of(c->cors_origins.begin(), c->cors_origins.end(),
                                       [&](const std::string& o) { return o == origin || o == "*"; });
    if (cors_ok) {
      res.set_header("Access-Control-Allow-Origin", origin);
      res.set_header("Vary", "Origin");
      res.set_header("Access-Control-Expose-Headers", "Location, ETag, Retry-After, Allow");
    }
    if (req.method == "OPTIONS") {
      if (!cors_ok) {
        send_problem(res, 403, "cross-origin requests from \"" + origin.substr(0, 200) +
                                   "\" are not allowed (--cors-origin)");
        return httplib::Server::HandlerResponse::Handled;
      }
      res.set_header("Access-Control-Allow-Methods", "GET, POST, PATCH, DELETE, OPTIONS");
      res.set_header("Access-Control-Allow-Headers",
                     "Authorization, Content-Type, Idempotency-Key, If-None-Match, Last-Event-ID");
      res.set_header("Access-Control-Max-Age", "600");
      res.status = 204;
      return httplib::Server::HandlerResponse::Handled;
    }
    if (c->auth.enabled() && !is_public(req) && !caller_of(*c, req).authenticated) {
      res.set_header("WWW-Authenticate", "Bearer realm=\"tessera\"");
      send_problem(res, 401, "a valid bearer token is required (Authorization: Bearer <token>)");
      return httplib::Server::HandlerResponse::Handled;
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
  server.set_payload_max_length(ctx.max_body_bytes);
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
  server.set_post_routing_handler([c](const Request& req, Response& res) {
    c->metrics.count_request(route_label(req), res.status);
  });
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
