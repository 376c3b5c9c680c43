// Helpers shared by the server unit tests.
#pragma once

#include <signal.h>
#include <sys/resource.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "server/base/job_id.h"
#include "server/jobs/submission.h"
#include "server/store/job_store.h"

namespace tessera::server::test {

// A queued scene job record with a fresh id, as the API would store it.
inline JobRecord make_job(int priority, int64_t created_at_ms) {
  JobRecord r;
  r.id = new_job_id();
  r.kind = "scene";
  r.priority = priority;
  r.created_at_ms = created_at_ms;
  r.document = R"({"kind":"scene"})";
  r.settings = R"({"width":64})";
  r.outputs = R"(["png"])";
  r.progress.samples_total = 16;
  return r;
}

inline std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// proto/examples/cornell.json, the reference job.
inline nlohmann::json cornell_job() {
  return nlohmann::json::parse(read_text(std::filesystem::path(TESSERA_SOURCE_DIR) / "proto/examples/cornell.json"));
}
// The reference job at size x size pixels and `spp` samples per pixel.
inline nlohmann::json cornell_job(int size, int spp) {
  nlohmann::json doc = cornell_job();
  doc["render"]["width"] = size;
  doc["render"]["height"] = size;
  doc["render"]["spp"] = spp;
  return doc;
}
// A job that renders until cancelled (on two threads, 65536 spp of 128x128 take minutes).
inline nlohmann::json long_cornell_job() {
  return cornell_job(128, 65536);
}

// The queued record POST /v1/jobs stores for `doc`, checked as the API checks it (the document must be valid), with a
// fresh id.
inline JobRecord accepted_job_record(const nlohmann::json& doc) {
  const AcceptedJob accepted = std::get<AcceptedJob>(check_job_document(doc, SubmissionLimits{}));
  JobRecord job;
  job.id = new_job_id();
  job.kind = accepted.kind;
  job.created_at_ms = 1;
  job.document = accepted.document.dump();
  job.settings = render_settings_text(accepted.settings);
  job.outputs = output_spec_text(accepted.outputs);
  job.progress.samples_total = accepted.settings.spp;
  return job;
}

// One triangle as an upload: tri.gltf, padded with `padding` bytes of extras (which loaders ignore), and its tri.bin;
// (file name, bytes) pairs.
inline std::vector<std::pair<std::string, std::string>> triangle_gltf(size_t padding = 0) {
  const float p[9] = {-1, -1, 0, 1, -1, 0, 0, 1, 0};
  nlohmann::json asset = {{"version", "2.0"}};
  if (padding > 0) asset["extras"] = {{"padding", std::string(padding, 'x')}};
  const nlohmann::json gltf = {{"asset", asset},
                               {"scene", 0},
                               {"scenes", {{{"nodes", {0}}}}},
                               {"nodes", {{{"mesh", 0}}}},
                               {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}}}}}}},
                               {"accessors",
                                {{{"bufferView", 0},
                                  {"componentType", 5126},
                                  {"count", 3},
                                  {"type", "VEC3"},
                                  {"min", {-1, -1, 0}},
                                  {"max", {1, 1, 0}}}}},
                               {"bufferViews", {{{"buffer", 0}, {"byteLength", 36}}}},
                               {"buffers", {{{"uri", "tri.bin"}, {"byteLength", 36}}}}};
  return {{"tri.gltf", gltf.dump()}, {"tri.bin", std::string(reinterpret_cast<const char*>(p), sizeof p)}};
}

// A fresh directory under the system temp dir, removed with the object.
class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = std::filesystem::temp_directory_path() / ("tessera-test-" + std::to_string(rd()) + std::to_string(rd()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// Polls until `done`, for at most `timeout_s`; false on timeout.
inline bool eventually(const std::function<bool()>& done, double timeout_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < deadline) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return done();
}

// Lowers the soft file-size limit of the process for the object's lifetime, SIGXFSZ ignored: a write past it fails
// with EFBIG (or comes short), as one on a full disk fails with ENOSPC. Files already larger stay readable.
class FileSizeLimit {
 public:
  explicit FileSizeLimit(rlim_t bytes) {
    getrlimit(RLIMIT_FSIZE, &saved_);
    old_handler_ = signal(SIGXFSZ, SIG_IGN);
    rlimit lowered = saved_;
    lowered.rlim_cur = bytes;
    setrlimit(RLIMIT_FSIZE, &lowered);
  }
  ~FileSizeLimit() {
    setrlimit(RLIMIT_FSIZE, &saved_);
    signal(SIGXFSZ, old_handler_);
  }
  FileSizeLimit(const FileSizeLimit&) = delete;
  FileSizeLimit& operator=(const FileSizeLimit&) = delete;

 private:
  rlimit saved_{};
  sighandler_t old_handler_ = SIG_DFL;
};

}  // namespace tessera::server::test
