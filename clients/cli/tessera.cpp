// tessera: the command-line tool.
//   tessera submit|watch|fetch|list|cancel ...   against a tesserad (--url, --token)
//   tessera render JOB.json|SCENE.glb -o out.png ... and tessera merge PART.tfilm... -o OUT: run tessera-render
//
// This program links no renderer: the renderer and its image libraries (a few hundred shared objects, most of a
// second to load) are in tessera-render, installed beside it, which `render` and `merge` run in its place.
#include <httplib.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <map>
#include <optional>
#include <thread>

#include <nlohmann/json.hpp>

#include "clients/cli/cli_common.h"
#include "proto/asset_path.h"
#include "renderer/frames.h"

namespace {

using namespace tessera::cli;
using nlohmann::json;

const char* kUsage =
    "usage: tessera COMMAND [options]\n"
    "\n"
    "local (no daemon):\n"
    "  render JOB.json|SCENE.glb|SCENE.gltf -o OUT [-o OUT...]   render a job or a glTF asset; OUT is .png, .exr\n"
    "                                       or .tfilm (a partial film for merge)\n"
    "  merge PART.tfilm... -o OUT           combine sample ranges / regions into one image (bit-exact)\n"
    "against a daemon (--url URL or TESSERA_URL, default http://127.0.0.1:8080; --token T or TESSERA_TOKEN):\n"
    "  submit JOB.json|SCENE.glb|SCENE.gltf [FILE...]   submit a job (multipart with files); prints its id\n"
    "  watch ID                             follow a job until it ends (events, or polling)\n"
    "  fetch ID [-d DIR] [-o FILE...]       download a finished job's results\n"
    "  list [--state S] [--limit N] [--json]\n"
    "  cancel ID\n"
    "  log ID                               print a job's log (loading, warnings, passes, how it ended)\n"
    "\n"
    "`tessera COMMAND -h` describes a command; `tessera --version` prints the version.\n"
    "exit codes: 0 done, 1 fatal (bad input, refused or failed job), 2 usage, 75 transient failure (retry)\n";

// ---------------------------------------------------------------------------------------------------------------
// The daemon's API

struct Remote {
  std::string url;
  std::string token;

  std::unique_ptr<httplib::Client> client(int read_timeout_s = 60) const {
    auto c = std::make_unique<httplib::Client>(url);
    if (!c->is_valid()) throw std::invalid_argument("bad --url " + url);
    c->set_connection_timeout(10, 0);
    c->set_read_timeout(read_timeout_s, 0);
    c->set_write_timeout(60, 0);
    if (!token.empty()) c->set_bearer_token_auth(token);
    return c;
  }
};

// Remote options shared by every daemon command; removes them from args.
Remote remote_options(std::vector<std::string>* args) {
  Remote r;
  const char* env_url = std::getenv("TESSERA_URL");
  const char* env_token = std::getenv("TESSERA_TOKEN");
  r.url = env_url && *env_url ? env_url : "http://127.0.0.1:8080";
  r.token = env_token ? env_token : "";
  std::vector<std::string> rest;
  for (size_t i = 0; i < args->size(); ++i) {
    const std::string& a = (*args)[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= args->size()) throw std::invalid_argument(a + " needs a value");
      return (*args)[++i];
    };
    if (a == "--url")
      r.url = value();
    else if (a == "--token")
      r.token = value();
    else
      rest.push_back(a);
  }
  while (!r.url.empty() && r.url.back() == '/') r.url.pop_back();
  if (r.url.rfind("http://", 0) != 0 && r.url.rfind("https://", 0) != 0)
    throw std::invalid_argument("--url must start with http:// or https://, not \"" + r.url + "\"");
  *args = std::move(rest);
  return r;
}

// Turns a failed exchange into a Failure: no answer or 5xx/429/503 is transient (75), any other 4xx fatal (1).
[[noreturn]] void http_failure(const Remote& remote, const httplib::Result& res, const std::string& what) {
  if (!res)
    retry(what + ": cannot reach " + remote.url + " (" + httplib::to_string(res.error()) +
          "): is tesserad running? (`make run` in the repository starts it; --url or TESSERA_URL names another)");
  std::string message = what + ": HTTP " + std::to_string(res->status);
  const json problem = json::parse(res->body, nullptr, false);
  if (problem.is_object()) {
    if (problem.contains("title") && problem["title"].is_string()) message += " " + problem["title"].get<std::string>();
    if (problem.contains("detail") && problem["detail"].is_string())
      message += ": " + problem["detail"].get<std::string>();
    auto at = [](const json& pointer) {
      return pointer.is_string()
                 ? " (at " + (pointer.get<std::string>().empty() ? "/" : pointer.get<std::string>()) + ")"
                 : std::string();
    };
    if (problem.contains("pointer")) message += at(problem["pointer"]);
    // A document with several errors: the first is the detail above, the others follow, one a line.
    if (problem.contains("errors") && problem["errors"].is_array())
      for (size_t i = 1; i < problem["errors"].size(); ++i) {
        const json& e = problem["errors"][i];
        if (e.is_object() && e.contains("detail") && e["detail"].is_string())
          message += "\ntessera: " + what + ": " + e["detail"].get<std::string>() + at(e.value("pointer", json()));
      }
    // The checks these errors kept from running, which follow once they are fixed.
    if (problem.contains("pending") && problem["pending"].is_string())
      message += "\ntessera: " + what + ": " + problem["pending"].get<std::string>();
  } else if (!res->body.empty()) {
    message += ": " + res->body.substr(0, 300);
  }
  if (res->status == 401) message += " (give a token with --token or TESSERA_TOKEN)";
  if (res->status >= 500 || res->status == 429 || res->status == 408) retry(message);
  fatal(message);
}

json expect_json(const Remote& remote, const httplib::Result& res, const std::string& what) {
  if (!res || res->status < 200 || res->status >= 300) http_failure(remote, res, what);
  json j = json::parse(res->body, nullptr, false);
  if (j.is_discarded()) retry(what + ": the daemon's answer is not JSON");
  return j;
}

std::string progress_line(const json& job) {
  const json& p = job.value("progress", json::object());
  char buf[256];
  const double frac = p.value("fraction", 0.0);
  std::string eta = "?";
  if (p.contains("eta_s") && p["eta_s"].is_number()) {
    char e[32];
    std::snprintf(e, sizeof e, "%.1fs", p["eta_s"].get<double>());
    eta = e;
  }
  std::snprintf(buf, sizeof buf, "%-9s %3.0f%%  %d/%d spp  pass %d  %.1fs  eta %s  %.3g samples/s",
                job.value("state", "?").c_str(), frac * 100, p.value("samples_done", 0), p.value("samples_total", 0),
                p.value("passes", 0), p.value("elapsed_s", 0.0), eta.c_str(), p.value("samples_per_s", 0.0));
  std::string line = buf;
  // A frame range: its frames done of all, and the one rendering.
  if (const json& f = job.value("frames", json()); f.is_object()) {
    line += "  frames " + std::to_string(f.value("done", 0)) + "/" + std::to_string(f.value("total", 0));
    if (const json& r = f.value("running_ranges", json::array()); !r.empty())
      line += " (rendering " + r[0][0].dump() + ")";
  }
  if (job.contains("stop_reason") && job["stop_reason"].is_string())
    line += "  stopped by " + job["stop_reason"].get<std::string>();
  if (job.contains("error") && job["error"].is_string()) line += "  error: " + job["error"].get<std::string>();
  return line;
}

std::string url_component(const std::string& s) {
  std::string out;
  for (unsigned char c : s) {
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == ',') {
      out += static_cast<char>(c);
    } else {
      char b[4];
      std::snprintf(b, sizeof b, "%%%02X", c);
      out += b;
    }
  }
  return out;
}

bool is_terminal(const std::string& s) {
  return s == "succeeded" || s == "failed" || s == "cancelled";
}

std::string job_path(const std::string& id) {
  for (char c : id)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_')
      throw std::invalid_argument("\"" + id + "\" is not a job id");
  return "/v1/jobs/" + id;
}

// The shortest start of a job id a command takes: one or two digits name a job of a handful by chance (`cancel 0`
// would cancel whichever job happened to start with 0).
constexpr size_t kMinIdPrefix = 4;

// The job an argument names: a whole id (32 hex digits), or the start of one (at least kMinIdPrefix digits; the web
// client shows 8) that exactly one of the caller's jobs has. A shorter start is a usage error; no match, or several,
// is a fatal error naming the candidates.
std::string resolve_job_id(const Remote& remote, const std::string& arg) {
  constexpr size_t kIdLength = 32;
  const bool hex = !arg.empty() && std::all_of(arg.begin(), arg.end(), [](unsigned char c) {
    return std::isdigit(c) || (c >= 'a' && c <= 'f');
  });
  if (hex && arg.size() < kMinIdPrefix)
    throw std::invalid_argument("\"" + arg + "\" is too short for a job id: give at least " +
                                std::to_string(kMinIdPrefix) +
                                " of its hex digits (the 8 the web client shows, or the 32 `tessera list` shows)");
  if (!hex || arg.size() >= kIdLength) {
    job_path(arg);  // a malformed argument is a usage error
    return arg;
  }
  auto client = remote.client();
  std::vector<json> matches;
  std::string cursor;
  do {
    const std::string query = "/v1/jobs?limit=1000" + (cursor.empty() ? "" : "&cursor=" + url_component(cursor));
    const json page = expect_json(remote, client->Get(query.c_str()), "find job " + arg);
    for (const json& j : page.value("jobs", json::array()))
      if (j.value("id", "").rfind(arg, 0) == 0) matches.push_back(j);
    cursor =
        page.contains("next_cursor") && page["next_cursor"].is_string() ? page["next_cursor"].get<std::string>() : "";
  } while (!cursor.empty());
  if (matches.size() == 1) return matches[0].value("id", "");
  if (matches.empty()) fatal("no job id starts with " + arg + " (tessera list shows the jobs)");
  std::string message = "the job id prefix " + arg + " is ambiguous: " + std::to_string(matches.size()) +
                        " jobs start with it; give more digits:";
  for (const json& j : matches)
    message += "\n  " + j.value("id", "") + "  " + j.value("state", "") + "  " + j.value("name", "");
  fatal(message);
}

// The positional arguments of a command, between lo and hi of them; what looks like an option is one the command
// does not know (its own options, `known`, were taken out before).
void require_args(const std::vector<std::string>& args, size_t lo, size_t hi, const char* usage,
                  std::initializer_list<std::string_view> known = {}) {
  for (const std::string& a : args)
    if (a == "-h" || a == "--help") {
      std::fputs(usage, stdout);
      throw Failure(kExitOk, "");
    }
  for (const std::string& a : args)
    if (a.size() > 1 && a[0] == '-') unknown_option(a, known);
  if (args.size() < lo || args.size() > hi) throw std::invalid_argument(std::string("wrong arguments\n") + usage);
}

const char* kSubmitUsage =
    "usage: tessera submit JOB.json|SCENE.glb|SCENE.gltf [FILE...] [--priority N] [--spp N] [--width N] [--height N]\n"
    "                      [--variant NAME] [--time SECONDS] [--animation NAME|N] [--watch] [--url URL] [--token T]\n"
    "Submits a job and prints its id. With a .glb/.gltf (and the .bin and images a .gltf needs) the job goes as\n"
    "multipart/form-data; a job document whose scene.gltf names a file beside it takes that file along.\n"
    "--variant chooses the glTF asset's KHR_materials_variants variant (scene.gltf_variant).\n"
    "--time renders a still of the glTF asset's animation at that time in seconds (scene.time); --animation chooses\n"
    "the animation by name or index (scene.animation; default the first).\n"
    "--watch follows the job until it ends (exit code as for watch).\n";

int cmd_watch_remote(const Remote& remote, const std::string& id, bool quiet);

int cmd_submit(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  std::vector<std::string> files;
  json overrides = json::object();
  std::optional<long long> priority;
  std::optional<std::string> variant;
  json scene_overrides = json::object();  // --time, --animation
  bool watch = false;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= args.size()) throw std::invalid_argument(a + " needs a value");
      return args[++i];
    };
    if (a == "-h" || a == "--help") {
      std::fputs(kSubmitUsage, stdout);
      return kExitOk;
    }
    if (a == "--priority")
      priority = parse_integer(a, value());
    else if (a == "--spp" || a == "--width" || a == "--height")
      overrides[a.substr(2)] = parse_integer(a, value());
    else if (a == "--variant")
      variant = value();
    else if (a == "--time")
      scene_overrides["time"] = parse_number(a, value());
    else if (a == "--animation")
      scene_overrides["animation"] = animation_choice(value());
    else if (a == "--watch")
      watch = true;
    else if (!a.empty() && a[0] == '-')
      unknown_option(a, {"--priority", "--spp", "--width", "--height", "--variant", "--time", "--animation", "--watch",
                         "--url", "--token", "--help"});
    else
      files.push_back(a);
  }
  if (files.empty()) throw std::invalid_argument(std::string("submit needs a job or a glTF file\n") + kSubmitUsage);

  json doc;
  std::vector<std::string> attachments;
  const std::string main = files.front();
  const std::string ext = lower_extension(main);
  if (ext == ".glb" || ext == ".gltf") {
    doc = {{"kind", "scene"}, {"scene", {{"gltf", std::filesystem::path(main).filename().string()}}}};
    attachments = files;
  } else {
    const std::string text = main == "-" ? std::string(std::istreambuf_iterator<char>(std::cin), {}) : read_file(main);
    doc = parse_json(text, main == "-" ? "the standard input" : main);
    if (!doc.is_object()) fatal(main + " is not a JSON object (a job document is {\"kind\": ...})");
    attachments.assign(files.begin() + 1, files.end());
    // A scene that names a glTF file beside the job document takes it along.
    if (attachments.empty() && main != "-" && doc.contains("scene") && doc["scene"].is_object() &&
        doc["scene"].contains("gltf") && doc["scene"]["gltf"].is_string()) {
      const auto asset = std::filesystem::path(main).parent_path() / doc["scene"]["gltf"].get<std::string>();
      std::error_code ec;
      if (std::filesystem::is_regular_file(asset, ec)) attachments.push_back(asset.string());
    }
  }
  if (!overrides.empty()) {
    if (!doc.contains("render") || !doc["render"].is_object()) doc["render"] = json::object();
    doc["render"].update(overrides);
  }
  if (priority) doc["priority"] = *priority;
  if (variant && doc.contains("scene") && doc["scene"].is_object()) doc["scene"]["gltf_variant"] = *variant;
  if (doc.contains("scene") && doc["scene"].is_object()) doc["scene"].update(scene_overrides);
  // A job is called by the file it was submitted from, unless its document names it.
  if (const std::string file = std::filesystem::path(main).filename().string();
      main != "-" && !doc.contains("name") && file.size() <= 200)
    doc["name"] = file;
  // A .gltf names its buffers and images: take those that sit beside it (or in its subfolders) along too, under the
  // names its URIs give them (proto/asset_path.h, as the daemon reads them).
  std::map<std::string, std::string> upload_names;  // attachment -> its name in the upload, when not its file name
  for (size_t i = 0; i < attachments.size(); ++i) {
    if (lower_extension(attachments[i]) != ".gltf") continue;
    json g = json::parse(read_file(attachments[i]), nullptr, false);
    if (!g.is_object()) continue;
    for (const char* key : {"buffers", "images"}) {
      for (const json& e : g.value(key, json::array())) {
        if (!e.is_object() || !e.contains("uri") || !e["uri"].is_string()) continue;
        const std::string uri = e["uri"].get<std::string>();
        const tessera::proto::AssetPath name = tessera::proto::asset_path_from_uri(uri);
        if (!name.problem.empty()) continue;  // a data: URI, or one the daemon refuses, naming it
        const auto file = (std::filesystem::path(attachments[i]).parent_path() / name.path).string();
        if (std::find(attachments.begin(), attachments.end(), file) != attachments.end()) continue;
        if (std::filesystem::exists(file)) {
          attachments.push_back(file);
          upload_names[file] = name.path;
          continue;
        }
        // Not beside the .gltf: sent by the caller under its name, else missing (said here, before the upload,
        // where the daemon could only say that the name is no file of the upload).
        const bool sent = std::any_of(attachments.begin(), attachments.end(), [&](const std::string& a) {
          const auto named = upload_names.find(a);
          return (named != upload_names.end() ? named->second : std::filesystem::path(a).filename().string()) ==
                 name.path;
        });
        if (!sent)
          fatal(name.path + " not found beside " + attachments[i] + " (which names it as " +
                (std::string_view(key) == "buffers" ? "a buffer" : "an image") +
                "): put it there, or give it as a FILE argument");
      }
    }
  }

  auto client = remote.client();
  auto post = [&]() -> httplib::Result {
    if (attachments.empty()) return client->Post("/v1/jobs", doc.dump(), "application/json");
    httplib::MultipartFormDataItems items;
    items.push_back({"job", doc.dump(), "job.json", "application/json"});
    for (const std::string& f : attachments) {
      const std::string e = lower_extension(f);
      const std::string type = e == ".glb"                   ? "model/gltf-binary"
                               : e == ".gltf"                ? "model/gltf+json"
                               : e == ".png"                 ? "image/png"
                               : e == ".jpg" || e == ".jpeg" ? "image/jpeg"
                                                             : "application/octet-stream";
      const auto named = upload_names.find(f);
      items.push_back({"file", read_file(f),
                       named != upload_names.end() ? named->second : std::filesystem::path(f).filename().string(),
                       type});
    }
    return client->Post("/v1/jobs", items);
  };
  const httplib::Result res = post();
  const json job = expect_json(remote, res, "submit");
  const std::string id = job.value("id", "");
  if (id.empty()) retry("submit: the daemon's answer has no job id");
  std::printf("%s\n", id.c_str());
  std::fflush(stdout);
  if (watch) return cmd_watch_remote(remote, id, false);
  return kExitOk;
}

const char* kWatchUsage =
    "usage: tessera watch ID [--interval S] [-q] [--url URL] [--token T]\n"
    "Follows a job until it ends: the daemon's Server-Sent Events, or polling every S seconds (default 1) when it\n"
    "has none. Exit code: 0 succeeded, 1 failed or cancelled, 75 the daemon could not be reached.\n";

double g_poll_interval_s = 1.0;

int exit_for_state(const json& job) {
  const std::string state = job.value("state", "");
  if (state == "succeeded") return kExitOk;
  if (job.contains("error") && job["error"].is_string())
    std::fprintf(stderr, "tessera: job %s: %s\n", state.c_str(), job["error"].get<std::string>().c_str());
  return kExitFatal;
}

// Follows the events stream. Returns the final job status, or nothing when the daemon has no events endpoint (404)
// or the stream ended early.
std::optional<json> watch_events(const Remote& remote, const std::string& id, bool quiet, bool* no_endpoint) {
  auto client = remote.client(45);  // the daemon sends a keep-alive comment every 15 s
  std::string buffer, event, data;
  std::optional<json> last;
  bool done = false;
  int status = 0;
  uint64_t last_id = 0;
  auto dispatch = [&]() {
    if (event.empty() && data.empty()) return;
    json d = json::parse(data, nullptr, false);
    if (event == "state" && d.is_object()) {
      last = d;
      if (!quiet) std::printf("%s\n", progress_line(d).c_str());
      if (is_terminal(d.value("state", ""))) done = true;
    } else if (event == "progress" && d.is_object() && last) {
      (*last)["progress"] = d.value("progress", json::object());
      if (!quiet) std::printf("%s\n", progress_line(*last).c_str());
    }
    std::fflush(stdout);
    event.clear();
    data.clear();
  };
  for (int attempt = 0; attempt < 5 && !done; ++attempt) {
    httplib::Headers headers = {{"Accept", "text/event-stream"}};
    if (last_id) headers.emplace("Last-Event-ID", std::to_string(last_id));
    auto res = client->Get((job_path(id) + "/events").c_str(), headers,
                           [&](const httplib::Response& r) {
                             status = r.status;
                             return r.status == 200;
                           },
                           [&](const char* bytes, size_t n) {
                             buffer.append(bytes, n);
                             size_t pos;
                             while ((pos = buffer.find('\n')) != std::string::npos) {
                               std::string line = buffer.substr(0, pos);
                               buffer.erase(0, pos + 1);
                               if (!line.empty() && line.back() == '\r') line.pop_back();
                               if (line.empty())
                                 dispatch();
                               else if (line.rfind("event:", 0) == 0)
                                 event = line.substr(line[6] == ' ' ? 7 : 6);
                               else if (line.rfind("data:", 0) == 0)
                                 data += (data.empty() ? "" : "\n") + line.substr(line[5] == ' ' ? 6 : 5);
                               else if (line.rfind("id:", 0) == 0)
                                 last_id = std::strtoull(line.c_str() + 3, nullptr, 10);
                               if (done) return false;
                             }
                             return true;
                           });
    if (done) return last;
    if (status == 404 && !last) {
      *no_endpoint = true;  // a daemon without events: poll
      return std::nullopt;
    }
    if (status != 0 && status != 200) {
      // An error answer (401, 404 for an unknown job, 5xx): read its problem with a plain request.
      http_failure(remote, client->Get((job_path(id) + "/events").c_str()), "watch");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // dropped: reconnect from last_id
  }
  return last && done ? last : std::nullopt;
}

int cmd_watch_remote(const Remote& remote, const std::string& id, bool quiet) {
  bool no_endpoint = false;
  if (auto final_job = watch_events(remote, id, quiet, &no_endpoint)) return exit_for_state(*final_job);
  auto client = remote.client();
  std::string previous;
  for (;;) {
    const json job = expect_json(remote, client->Get(job_path(id).c_str()), "watch");
    const std::string line = progress_line(job);
    if (!quiet && line != previous) std::printf("%s\n", line.c_str());
    std::fflush(stdout);
    previous = line;
    if (is_terminal(job.value("state", ""))) return exit_for_state(job);
    std::this_thread::sleep_for(std::chrono::duration<double>(g_poll_interval_s));
  }
}

int cmd_watch(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  bool quiet = false;
  std::vector<std::string> rest;
  for (size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "-q" || args[i] == "--quiet")
      quiet = true;
    else if (args[i] == "--interval") {
      if (i + 1 >= args.size()) throw std::invalid_argument("--interval needs a value");
      g_poll_interval_s = parse_number("--interval", args[++i]);
      if (g_poll_interval_s <= 0) throw std::invalid_argument("--interval must be positive");
    } else
      rest.push_back(args[i]);
  }
  require_args(rest, 1, 1, kWatchUsage, {"--interval", "--quiet", "--url", "--token", "--help"});
  return cmd_watch_remote(remote, resolve_job_id(remote, rest[0]), quiet);
}

const char* kFetchUsage =
    "usage: tessera fetch ID [-d DIR] [-o FILE.png|FILE.exr ...] [--url URL] [--token T]\n"
    "Downloads a finished job's results: to the -o files, else every output the job has into DIR (default .) as\n"
    "ID.png and ID.exr. A job cancelled after a pass has the image of that pass as its (partial) results.\n"
    "A frame range job's results are its frames done, each output numbered (ID.0001.png, FILE.0001.exr), with one\n"
    "progress line.\n"
    "Exit code 75 while the job has not finished yet, 1 when it has no results (it failed, or was cancelled before\n"
    "its first pass).\n";

// The frames done of a frame range job (its status's frames.done_ranges): each output of each frame, to the -o files
// numbered as renderer/frames.h numbers a sequence, else to DIR/ID.<frame>.<ext>. One progress line, on stderr.
int fetch_frames(const Remote& remote, httplib::Client& client, const std::string& id, const json& job,
                 const std::string& dir, std::vector<std::string> outputs) {
  const json& f = job["frames"];
  const tessera::FrameRange range{f.value("start", int64_t{0}), f.value("end", int64_t{0}), f.value("step", int64_t{1}),
                                  1};
  const int padding = tessera::frame_padding(range);
  if (outputs.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) fatal("cannot make the directory " + dir + ": " + ec.message());
    for (const json& o : job.value("outputs", json::array()))
      if (o.is_string()) outputs.push_back((std::filesystem::path(dir) / (id + "." + o.get<std::string>())).string());
  }
  std::vector<int64_t> frames;
  for (const json& r : f.value("done_ranges", json::array()))
    for (int64_t n = r[0].get<int64_t>(); n <= r[1].get<int64_t>(); n += range.step) frames.push_back(n);
  if (frames.empty()) {
    if (!is_terminal(job.value("state", ""))) retry("job " + id + " has no frame done yet");
    fatal("job " + id + " " + job.value("state", "") + ": none of its frames is done");
  }
  for (const std::string& out : outputs)
    for (int64_t n : frames) check_writable(tessera::frame_path(out, n, padding).string());
  size_t fetched = 0;
  for (int64_t n : frames) {
    for (const std::string& out : outputs) {
      const std::string ext = lower_extension(out).substr(1);
      auto res = client.Get((job_path(id) + "/frames/" + std::to_string(n) + "/result." + ext).c_str());
      if (!res || res->status != 200) http_failure(remote, res, "fetch frame " + std::to_string(n) + " " + ext);
      write_file_atomic(tessera::frame_path(out, n, padding).string(), res->body);
    }
    ++fetched;
    std::fprintf(stderr, "\rtessera: fetched %zu/%zu frames (frame %lld)", fetched, frames.size(),
                 static_cast<long long>(n));
  }
  std::fprintf(stderr, "\n");
  for (const std::string& out : outputs)
    std::printf("%s\n", tessera::frame_path(out, frames.front(), padding).string().c_str());
  if (frames.size() < static_cast<size_t>(f.value("total", 0)))
    std::fprintf(stderr, "tessera: job %s %s: %zu of its %d frames are done\n", id.c_str(),
                 job.value("state", "").c_str(), frames.size(), f.value("total", 0));
  return kExitOk;
}

int cmd_fetch(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  std::string dir = ".";
  std::vector<std::string> outputs, rest;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if ((a == "-d" || a == "--dir" || a == "-o" || a == "--output") && i + 1 >= args.size())
      throw std::invalid_argument(a + " needs a value");
    if (a == "-d" || a == "--dir")
      dir = args[++i];
    else if (a == "-o" || a == "--output")
      outputs.push_back(args[++i]);
    else if (a != "-h" && a != "--help" && !a.empty() && a[0] == '-')
      unknown_option(a, {"--dir", "--output", "--url", "--token", "--help"});
    else
      rest.push_back(a);
  }
  require_args(rest, 1, 1, kFetchUsage);
  const std::string id = resolve_job_id(remote, rest[0]);
  for (const std::string& o : outputs)
    if (lower_extension(o) != ".png" && lower_extension(o) != ".exr")
      throw std::invalid_argument(o + ": fetch writes .png or .exr files");
  for (const std::string& o : outputs) check_writable(o);
  auto client = remote.client();
  const json job = expect_json(remote, client->Get(job_path(id).c_str()), "fetch");
  const std::string state = job.value("state", "");
  if (job.value("frames", json()).is_object()) return fetch_frames(remote, *client, id, job, dir, outputs);
  if (!is_terminal(state)) retry("job " + id + " is " + state + ": results exist once it has succeeded");
  // The status links the results there are: a succeeded job's outputs, and the image of the last complete pass of a
  // job cancelled after one (its partial results).
  const json links = job.value("links", json::object());
  std::vector<std::string> linked;
  for (const json& o : job.value("outputs", json::array()))
    if (o.is_string() && links.contains("result_" + o.get<std::string>())) linked.push_back(o.get<std::string>());
  if (linked.empty()) fatal("job " + id + " " + state + ": it has no results");
  if (state != "succeeded") {
    const json progress = job.value("progress", json::object());
    std::fprintf(stderr, "tessera: job %s %s: its results are a partial image of %lld of %lld samples per pixel\n",
                 id.c_str(), state.c_str(), progress.value("samples_done", 0LL), progress.value("samples_total", 0LL));
  }
  if (outputs.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) fatal("cannot make the directory " + dir + ": " + ec.message());
    for (const std::string& ext : linked) outputs.push_back((std::filesystem::path(dir) / (id + "." + ext)).string());
    for (const std::string& o : outputs) check_writable(o);
  }
  for (const std::string& out : outputs) {
    const std::string ext = lower_extension(out).substr(1);
    auto res = client->Get((job_path(id) + "/result." + ext).c_str());
    if (!res || res->status != 200) http_failure(remote, res, "fetch " + ext);
    write_file_atomic(out, res->body);
    std::printf("%s\n", out.c_str());
  }
  return kExitOk;
}

const char* kListUsage =
    "usage: tessera list [--state S] [--limit N] [--json] [--url URL] [--token T]\n"
    "Lists jobs, newest first: id, state, priority, samples, created, name. Every command that takes a job ID\n"
    "also takes the start of one that only one job has: at least 4 digits (the web client shows 8).\n";

int cmd_list(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  std::string query;
  bool as_json = false;
  std::vector<std::string> rest;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if ((a == "--state" || a == "--limit") && i + 1 >= args.size()) throw std::invalid_argument(a + " needs a value");
    if (a == "--state")
      query += std::string(query.empty() ? "?" : "&") + "state=" + url_component(args[++i]);
    else if (a == "--limit")
      query += std::string(query.empty() ? "?" : "&") + "limit=" + std::to_string(parse_integer(a, args[++i]));
    else if (a == "--json")
      as_json = true;
    else
      rest.push_back(a);
  }
  require_args(rest, 0, 0, kListUsage, {"--state", "--limit", "--json", "--url", "--token", "--help"});
  auto client = remote.client();
  const json list = expect_json(remote, client->Get(("/v1/jobs" + query).c_str()), "list");
  if (as_json) {
    std::printf("%s\n", list.dump(2).c_str());
    return kExitOk;
  }
  // A header over the rows' columns: the id's 32 digits, the state, the priority, samples done of the total, when
  // the job was created (as wide as its timestamps), its name.
  const json jobs = list.value("jobs", json::array());
  int created_width = 7;
  for (const json& j : jobs) created_width = std::max<int>(created_width, j.value("created_at", "").size());
  std::printf("%-32s  %-9s  %4s  %-17s  %-*s  %s\n", "ID", "STATE", "PRIO", "SAMPLES", created_width, "CREATED",
              "NAME");
  for (const json& j : jobs) {
    const json& p = j.value("progress", json::object());
    std::printf("%s  %-9s  %4d  %6d/%-6d spp  %s  %s\n", j.value("id", "").c_str(), j.value("state", "").c_str(),
                j.value("priority", 0), p.value("samples_done", 0), p.value("samples_total", 0),
                j.value("created_at", "").c_str(), j.value("name", "").c_str());
  }
  return kExitOk;
}

const char* kCancelUsage =
    "usage: tessera cancel ID [--url URL] [--token T]\n"
    "Cancels a queued, paused or running job and prints its state, cancelled (a running render stops within a\n"
    "tile's time; exit 1 when the job had already ended).\n";

int cmd_cancel(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  require_args(args, 1, 1, kCancelUsage, {"--url", "--token", "--help"});
  const std::string id = resolve_job_id(remote, args[0]);
  auto client = remote.client();
  const httplib::Result res = client->Post((job_path(id) + "/cancel").c_str());
  const json job = expect_json(remote, res, "cancel");
  std::printf("%s\n", job.value("state", "").c_str());
  return kExitOk;
}

const char* kLogUsage =
    "usage: tessera log ID [--url URL] [--token T]\n"
    "Prints a job's log: how long loading took, its warnings, each pass, how and why it ended (empty until the job\n"
    "starts rendering).\n";

int cmd_log(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  require_args(args, 1, 1, kLogUsage, {"--url", "--token", "--help"});
  const std::string id = resolve_job_id(remote, args[0]);
  auto client = remote.client();
  auto res = client->Get((job_path(id) + "/log").c_str());
  if (!res || res->status != 200) http_failure(remote, res, "log");
  std::fwrite(res->body.data(), 1, res->body.size(), stdout);
  return kExitOk;
}

// Runs tessera-render (beside this program, else on the PATH) with this command line: it does not return unless
// the program cannot be run.
int run_local(char** argv) {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  const std::string beside = ec ? std::string() : (self.parent_path() / "tessera-render").string();
  if (!beside.empty() && ::access(beside.c_str(), X_OK) == 0) {
    argv[0] = const_cast<char*>(beside.c_str());
    ::execv(beside.c_str(), argv);
  } else {
    argv[0] = const_cast<char*>("tessera-render");
    ::execvp("tessera-render", argv);
  }
  const int error = errno;
  std::fprintf(stderr, "tessera: cannot run tessera-render, which does `tessera %s` (it belongs beside %s): %s\n",
               argv[1], ec ? "tessera" : self.string().c_str(), std::strerror(error));
  return error == ENOENT || error == EACCES || error == ENOEXEC ? kExitFatal : kExitRetry;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fputs(kUsage, stderr);
    return kExitUsage;
  }
  const std::string cmd = argv[1];
  if (cmd == "--version" || cmd == "-V") {
    std::printf("tessera %s\n", TESSERA_VERSION);
    return kExitOk;
  }
  if (cmd == "render" || cmd == "merge") return run_local(argv);
  std::vector<std::string> args(argv + 2, argv + argc);
  return run_command([&] {
    if (cmd == "submit") return cmd_submit(args);
    if (cmd == "watch") return cmd_watch(args);
    if (cmd == "fetch") return cmd_fetch(args);
    if (cmd == "list") return cmd_list(args);
    if (cmd == "cancel") return cmd_cancel(args);
    if (cmd == "log") return cmd_log(args);
    if (cmd == "-h" || cmd == "--help" || cmd == "help") {
      std::fputs(kUsage, stdout);
      return kExitOk;
    }
    const std::string suggestion = tessera::proto::did_you_mean(
        cmd, {"render", "merge", "submit", "watch", "fetch", "list", "cancel", "log", "--help"});
    std::fprintf(stderr, "tessera: unknown command '%s'%s\n\n%s", cmd.c_str(), suggestion.c_str(), kUsage);
    return kExitUsage;
  });
}
