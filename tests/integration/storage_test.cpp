// Disk space and retention, with the real daemon: --min-free-disk above any disk refuses every request that would
// store client data (507, a problem document, nothing written) while reads go on; --retain-finished deletes ended
// jobs (row and folder) once they are older than the retention and never touches queued, running or paused ones.
#include <signal.h>

#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <set>
#include <sstream>
#include <thread>
#include <vector>

#include "proto/contract.h"
#include "tests/integration/daemon.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

// One triangle in a .gltf with its .bin (test::triangle_gltf) as multipart files: a valid upload.
httplib::MultipartFormDataItems triangle_files(size_t padding = 0) {
  httplib::MultipartFormDataItems items;
  for (auto& [name, bytes] : triangle_gltf(padding)) {
    const char* type = name == "tri.gltf" ? "model/gltf+json" : "application/octet-stream";
    items.push_back({"file", std::move(bytes), name, type});
  }
  return items;
}

std::string submit(httplib::Client& c, const json& doc) {
  auto res = c.Post("/v1/jobs", doc.dump(), "application/json");
  if (!res || res->status != 202) {
    ADD_FAILURE() << "submit: " << (res ? std::to_string(res->status) + " " + res->body : "no answer");
    return "";
  }
  return json::parse(res->body).value("id", "");
}

int status_of(httplib::Client& c, const std::string& path) {
  auto res = c.Get(path);
  return res ? res->status : -1;
}

std::string state_of(httplib::Client& c, const std::string& id) {
  auto res = c.Get("/v1/jobs/" + id);
  if (!res || res->status != 200) return res ? std::to_string(res->status) : "no answer";
  return json::parse(res->body).value("state", "");
}

// The words of the --min-free-disk refusal's detail.
const std::vector<std::string> kBelowMinimum = {"bytes available", "--min-free-disk", "nothing was stored"};

// A 507 problem document whose detail holds `words`.
void expect_507(const httplib::Result& res, const std::string& what, const std::vector<std::string>& words) {
  ASSERT_TRUE(res) << what << ": no answer";
  EXPECT_EQ(res->status, 507) << what << ": " << res->body;
  EXPECT_EQ(res->get_header_value("Content-Type"), "application/problem+json") << what;
  const json body = json::parse(res->body, nullptr, false);
  ASSERT_TRUE(body.is_object()) << what << ": " << res->body;
  EXPECT_FALSE(proto::contract_schemas().validate(body, "problem.schema.json")) << what << ": " << body.dump();
  EXPECT_EQ(body.value("status", 0), 507) << what;
  EXPECT_EQ(body.value("type", ""), "https://tessera.dev/problems/insufficient-storage") << what;
  const std::string detail = body.value("detail", "");
  for (const std::string& word : words) EXPECT_NE(detail.find(word), std::string::npos) << what << ": " << detail;
}

size_t entries_in(const fs::path& dir) {
  if (!fs::exists(dir)) return 0;
  return static_cast<size_t>(std::distance(fs::directory_iterator(dir), fs::directory_iterator()));
}

TEST(StorageGuard, ANearlyFullDiskRefusesNewJobsAndUploadsAndServesReads) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  // 1000 TiB free is more than any disk the test runs on; a month's retention sweeps once a minute.
  Daemon daemon(data, {"--threads", "1", "--min-free-disk", "1000TiB", "--retain-finished", "30d"});
  auto c = daemon.client();

  expect_507(c->Post("/v1/jobs", cornell_job(16, 2).dump(), "application/json"), "scene job", kBelowMinimum);
  expect_507(c->Post("/v1/jobs",
                     json{{"kind", "material"},
                          {"material", {{"type", "lambert"}}},
                          {"render", {{"width", 32}, {"height", 32}, {"spp", 4}}}}
                         .dump(),
                     "application/json"),
             "material job", kBelowMinimum);
  httplib::MultipartFormDataItems multipart = triangle_files();
  multipart.push_back(
      {"job",
       json{{"kind", "scene"}, {"scene", {{"gltf", "tri.gltf"}}}, {"render", {{"width", 8}, {"height", 8}}}}.dump(), "",
       "application/json"});
  expect_507(c->Post("/v1/jobs", multipart), "multipart job with its glTF", kBelowMinimum);
  expect_507(c->Post("/v1/assets", triangle_files()), "multipart asset", kBelowMinimum);
  expect_507(c->Post("/v1/assets?name=tri.gltf", triangle_files()[0].content, "model/gltf+json"), "raw asset",
             kBelowMinimum);

  // Reads go on.
  auto list = c->Get("/v1/jobs");
  ASSERT_TRUE(list);
  EXPECT_EQ(list->status, 200);
  EXPECT_TRUE(json::parse(list->body)["jobs"].empty()) << list->body;
  for (const char* path : {"/livez", "/v1/materials", "/v1/openapi.json"}) EXPECT_EQ(status_of(*c, path), 200) << path;
  EXPECT_EQ(status_of(*c, "/v1/jobs/0123456789abcdef0123456789abcdef"), 404);
  auto ready = c->Get("/readyz");
  ASSERT_TRUE(ready);
  EXPECT_EQ(ready->status, 200) << ready->body;
  const json storage = json::parse(ready->body)["storage"];
  EXPECT_EQ(storage["min_free_disk_bytes"], 1000ull << 40) << ready->body;
  EXPECT_TRUE(storage["available_bytes"].is_number_unsigned()) << ready->body;
  EXPECT_EQ(storage["below_minimum"], true) << ready->body;
  auto metrics = c->Get("/metrics");
  ASSERT_TRUE(metrics);
  EXPECT_EQ(metrics->status, 200);
  for (const std::string& name :
       {"tessera_min_free_disk_bytes " + std::to_string(1000ull << 40) + "\n",
        std::string("tessera_data_dir_available_bytes "), std::string("tessera_jobs_expired_total 0\n"),
        std::string("tessera_http_requests_total{route=\"/v1/jobs\",code=\"507\"} 3\n")})
    EXPECT_NE(metrics->body.find(name), std::string::npos) << name << "\n" << metrics->body;

  // Nothing of the refused requests was stored.
  EXPECT_EQ(entries_in(data / "jobs"), 0u);
  EXPECT_EQ(entries_in(data / "assets"), 0u);

  // SIGTERM: the sweeper, between two sweeps a minute apart, does not hold the exit up.
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(daemon.stop(SIGTERM), 0);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
}

// The disk fills between the --min-free-disk check and the write (here a 1 MiB file-size limit the daemon inherits,
// EFBIG, standing in for another process filling the disk, ENOSPC): the upload and the job are refused with 507 and
// the problem of the check, nothing of them is left, and the daemon goes on serving what fits.
TEST(StorageGuard, ADiskThatFillsDuringTheWriteIs507AndLeavesNothing) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  std::unique_ptr<Daemon> daemon;
  {
    FileSizeLimit limit(1 << 20);  // inherited through fork and exec; the test writes nothing meanwhile
    daemon = std::make_unique<Daemon>(data, std::vector<std::string>{"--threads", "1", "--min-free-disk", "0"});
  }
  auto c = daemon->client();
  const std::vector<std::string> ran_out = {"ran out of space", "nothing was stored"};

  expect_507(c->Post("/v1/assets", triangle_files(2 << 20)), "a 2 MiB asset", ran_out);
  EXPECT_EQ(entries_in(data / "assets"), 0u);  // no temp dir, no half asset

  // A job document of 2 MiB (unused materials with long names): SQLite cannot append it to its log.
  json big = cornell_job(16, 1);
  for (int i = 0; i < 8192; ++i)
    big["scene"]["materials"][std::string(240, 'm') + std::to_string(i)] = {{"type", "lambert"}};
  expect_507(c->Post("/v1/jobs", big.dump(), "application/json"), "a 2 MiB job", ran_out);
  // The same job as a multipart submission with a small glTF: the glTF fits and is kept (whole: a retry reuses it),
  // the job does not, and the detail says which.
  httplib::MultipartFormDataItems multipart = triangle_files();
  big["scene"]["gltf"] = "tri.gltf";
  multipart.push_back({"job", big.dump(), "", "application/json"});
  expect_507(c->Post("/v1/jobs", multipart), "a 2 MiB multipart job",
             {"ran out of space", "the job was not stored", "a retry reuses them"});
  EXPECT_EQ(entries_in(data / "assets"), 1u);
  auto list = c->Get("/v1/jobs");
  ASSERT_TRUE(list);
  EXPECT_TRUE(json::parse(list->body)["jobs"].empty()) << list->body;
  EXPECT_EQ(entries_in(data / "jobs"), 0u);

  // What fits is stored and rendered as ever.
  auto small = c->Post("/v1/assets", triangle_files());
  ASSERT_TRUE(small);
  EXPECT_EQ(small->status, 200) << small->body;  // kept from the multipart job
  const std::string id = submit(*c, cornell_job(16, 1));
  EXPECT_TRUE(eventually([&] { return state_of(*c, id) == "succeeded"; }, 60)) << state_of(*c, id);
  const std::string metrics = c->Get("/metrics")->body;
  // The two jobs were refused by the job store (its insert ran out of space), the asset by the file write: the store's
  // error count has the two.
  for (const char* line :
       {"tessera_http_requests_total{route=\"/v1/assets\",code=\"507\"} 1\n",
        "tessera_http_requests_total{route=\"/v1/jobs\",code=\"507\"} 2\n", "tessera_job_store_errors_total 2\n"})
    EXPECT_NE(metrics.find(line), std::string::npos) << line << metrics;
  EXPECT_EQ(daemon->stop(SIGTERM), 0);
}

TEST(RetentionSweep, FinishedJobsExpireAndQueuedRunningPausedJobsStay) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  Daemon daemon(data, {"--threads", "2", "--max-jobs", "2", "--retain-finished", "2s", "--log-level", "debug"});
  auto c = daemon.client();

  const std::string running = submit(*c, long_cornell_job());
  const std::string tiny = submit(*c, cornell_job(16, 4));
  ASSERT_TRUE(eventually([&] { return state_of(*c, tiny) == "succeeded"; }, 30)) << state_of(*c, tiny);
  EXPECT_TRUE(fs::is_directory(data / "jobs" / tiny));
  const std::string running2 = submit(*c, long_cornell_job());  // takes the slot the tiny job left
  const std::string queued = submit(*c, long_cornell_job());    // both slots busy: waits
  const std::string paused = submit(*c, long_cornell_job());
  const std::string cancelled = submit(*c, long_cornell_job());
  auto res = c->Post("/v1/jobs/" + paused + "/pause");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << res->body;
  res = c->Post("/v1/jobs/" + cancelled + "/cancel");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << res->body;

  // The sweep runs every second: the ended jobs go within about 3 s of ending, the row first, then the folder (as
  // DELETE /v1/jobs/{id} removes them).
  auto gone = [&](const std::string& id) {
    return status_of(*c, "/v1/jobs/" + id) == 404 && !fs::exists(data / "jobs" / id);
  };
  EXPECT_TRUE(eventually([&] { return gone(tiny) && gone(cancelled); }, 30))
      << state_of(*c, tiny) << " " << state_of(*c, cancelled) << "\n"
      << daemon.log();
  // Another sweep later, the jobs that have not ended are all still there, each older than the retention.
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  EXPECT_EQ(state_of(*c, running), "running");
  EXPECT_EQ(state_of(*c, running2), "running");
  EXPECT_EQ(state_of(*c, queued), "queued");
  EXPECT_EQ(state_of(*c, paused), "paused");
  EXPECT_TRUE(fs::is_directory(data / "jobs" / running));
  auto list = c->Get("/v1/jobs");
  ASSERT_TRUE(list);
  EXPECT_EQ(json::parse(list->body)["jobs"].size(), 4u) << list->body;

  EXPECT_NE(c->Get("/metrics")->body.find("tessera_jobs_expired_total 2\n"), std::string::npos);
  // One JSON log line per expired job, naming it.
  std::set<std::string> expired;
  std::istringstream log(daemon.log());
  for (std::string line; std::getline(log, line);) {
    const json entry = json::parse(line, nullptr, false);
    if (entry.is_object() && entry.value("msg", "") == "finished job expired") expired.insert(entry.value("job", ""));
  }
  EXPECT_EQ(expired, (std::set<std::string>{tiny, cancelled})) << daemon.log();
}

}  // namespace
}  // namespace tessera::server::test
