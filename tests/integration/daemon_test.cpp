// The real daemon over real HTTP: a Cornell box goes in, PNG and EXR come out and read back; previews while running;
// cancel; bad documents answered 4xx with the field named; restarts lose nothing.
#include <signal.h>

#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <functional>
#include <thread>

#include "proto/contract.h"
#include "renderer/image_io.h"
#include "tests/integration/daemon.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const std::vector<std::string> kDaemonArgs = {
    "--threads",   "2",     "--max-jobs",       "2",       "--max-width",      "2048",     "--max-height", "2048",
    "--log-level", "debug", "--max-body-bytes", "1048576", "--max-film-bytes", "300000000"};

std::string submit(httplib::Client& c, const json& doc, json* status = nullptr) {
  auto res = c.Post("/v1/jobs", doc.dump(), "application/json");
  if (!res) {
    ADD_FAILURE() << "no answer";
    return "";
  }
  EXPECT_EQ(res->status, 202) << res->body;
  json body = json::parse(res->body);
  EXPECT_EQ(res->get_header_value("Location"), "/v1/jobs/" + body.value("id", ""));
  if (status) *status = body;
  return body.value("id", "");
}

json get_job(httplib::Client& c, const std::string& id) {
  auto res = c.Get("/v1/jobs/" + id);
  if (!res || res->status != 200) return json();
  return json::parse(res->body);
}

// Polls a job until `done` says so; returns its last status.
json wait_for(httplib::Client& c, const std::string& id, const std::function<bool(const json&)>& done,
              double timeout_s = 40) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  json status;
  while (std::chrono::steady_clock::now() < deadline) {
    status = get_job(c, id);
    if (!status.is_null() && done(status)) return status;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ADD_FAILURE() << "timed out waiting for job " << id << "; last status " << status.dump();
  return status;
}

bool in_state(const json& s, const char* state) {
  return s.value("state", "") == state;
}

std::string fetch(httplib::Client& c, const std::string& path, int expect_status = 200) {
  auto res = c.Get(path);
  if (!res) {
    ADD_FAILURE() << "no answer for " << path;
    return "";
  }
  EXPECT_EQ(res->status, expect_status) << path << ": " << res->body;
  return res->body;
}

ImageData decode(const std::string& bytes, const fs::path& as) {
  {
    std::ofstream out(as, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }
  return read_image(as.string());
}

double mean(const ImageData& img) {
  double sum = 0;
  for (float v : img.pixels) sum += v;
  return img.pixels.empty() ? 0 : sum / static_cast<double>(img.pixels.size());
}

void expect_problem(const httplib::Result& res, int status, const std::optional<std::string>& pointer,
                    const std::string& what) {
  ASSERT_TRUE(res) << what << ": no answer";
  EXPECT_EQ(res->status, status) << what << ": " << res->body;
  EXPECT_EQ(res->get_header_value("Content-Type"), "application/problem+json") << what;
  json body = json::parse(res->body, nullptr, false);
  ASSERT_TRUE(body.is_object()) << what << ": " << res->body;
  auto e = proto::contract_schemas().validate(body, "problem.schema.json");
  EXPECT_FALSE(e) << what << ": " << body.dump();
  EXPECT_EQ(body.value("status", 0), status) << what;
  if (pointer) {
    EXPECT_EQ(body.value("pointer", std::string("<none>")), *pointer) << what << ": " << body.dump();
  }
}

class DaemonTest : public testing::Test {
 protected:
  void SetUp() override {
    data_ = dir_.path() / "data";
    daemon_ = std::make_unique<Daemon>(data_, kDaemonArgs);
    client_ = daemon_->client();
  }
  void TearDown() override {
    if (HasFailure() && daemon_) std::fprintf(stderr, "--- tesserad log ---\n%s\n", daemon_->log().c_str());
  }

  TempDir dir_;
  fs::path data_;
  std::unique_ptr<Daemon> daemon_;
  std::unique_ptr<httplib::Client> client_;
};

TEST_F(DaemonTest, RendersTheCornellBox) {
  json queued;
  const std::string id = submit(*client_, cornell_job(64, 16), &queued);
  ASSERT_FALSE(id.empty());
  EXPECT_FALSE(proto::contract_schemas().validate(queued, "job-status.schema.json"));

  const json done = wait_for(*client_, id, [](const json& s) {
    return s.value("state", "") != "queued" && s.value("state", "") != "running";
  });
  ASSERT_EQ(done.value("state", ""), "succeeded") << done.dump();
  auto e = proto::contract_schemas().validate(done, "job-status.schema.json");
  EXPECT_FALSE(e) << e->pointer << " " << e->message;
  EXPECT_EQ(done["progress"]["samples_done"], 16);
  EXPECT_EQ(done["progress"]["fraction"], 1.0);
  EXPECT_GT(done["progress"]["samples_per_s"].get<double>(), 0);
  EXPECT_EQ(done["stop_reason"], "samples");
  EXPECT_EQ(done["render"]["width"], 64);

  const ImageData png = decode(fetch(*client_, "/v1/jobs/" + id + "/result.png"), dir_.path() / "r.png");
  EXPECT_EQ(png.width, 64);
  EXPECT_EQ(png.height, 64);
  EXPECT_GT(mean(png), 0.05);  // a lit box, not black
  const ImageData exr = decode(fetch(*client_, "/v1/jobs/" + id + "/result.exr"), dir_.path() / "r.exr");
  EXPECT_EQ(exr.width, 64);
  EXPECT_EQ(exr.height, 64);
  EXPECT_GE(exr.channels, 3);
  EXPECT_GT(mean(exr), 0.01);

  // The list shows it, newest first, and filters by state.
  json list = json::parse(fetch(*client_, "/v1/jobs?state=succeeded&limit=10"));
  ASSERT_FALSE(list["jobs"].empty());
  EXPECT_EQ(list["jobs"][0]["id"], id);
  EXPECT_TRUE(json::parse(fetch(*client_, "/v1/jobs?state=failed"))["jobs"].empty());
  // Cancelling a finished job is a conflict.
  expect_problem(client_->Post("/v1/jobs/" + id + "/cancel"), 409, std::nullopt, "cancel finished");
}

// Render passes: layers of result.exr, and each alone as PNG with the results' caching; only those the job asked for.
TEST_F(DaemonTest, RendersPassesIntoTheExrAndEachAsPng) {
  json doc = cornell_job(48, 8);
  doc["render"]["aovs"] = {"object_id", "albedo", "depth"};
  const std::string id = submit(*client_, doc);
  ASSERT_FALSE(id.empty());
  const json done =
      wait_for(*client_, id, [](const json& s) { return in_state(s, "succeeded") || in_state(s, "failed"); });
  ASSERT_TRUE(in_state(done, "succeeded")) << done.dump();
  EXPECT_FALSE(proto::contract_schemas().validate(done, "job-status.schema.json"));
  EXPECT_EQ(done["render"]["aovs"], json({"albedo", "depth", "object_id"}));  // the table's order
  EXPECT_EQ(done["links"]["aovs"]["depth"], "/v1/jobs/" + id + "/aovs/depth.png");

  // The beauty and the passes' 3 + 1 + 1 channels.
  const ImageData exr = decode(fetch(*client_, "/v1/jobs/" + id + "/result.exr"), dir_.path() / "r.exr");
  EXPECT_EQ(exr.channels, 8);

  auto albedo = client_->Get("/v1/jobs/" + id + "/aovs/albedo.png");
  ASSERT_TRUE(albedo);
  ASSERT_EQ(albedo->status, 200) << albedo->body;
  EXPECT_EQ(albedo->get_header_value("Content-Type"), "image/png");
  const ImageData look = decode(albedo->body, dir_.path() / "a.png");
  EXPECT_EQ(look.width, 48);
  EXPECT_GT(mean(look), 0.1);
  const std::string etag = albedo->get_header_value("ETag");
  ASSERT_FALSE(etag.empty());
  auto again = client_->Get("/v1/jobs/" + id + "/aovs/albedo.png", {{"If-None-Match", etag}});
  ASSERT_TRUE(again);
  EXPECT_EQ(again->status, 304);
  // Each pass its own picture.
  EXPECT_NE(fetch(*client_, "/v1/jobs/" + id + "/aovs/object_id.png"), albedo->body);

  auto not_asked = client_->Get("/v1/jobs/" + id + "/aovs/normal.png");
  expect_problem(not_asked, 404, std::nullopt, "a pass not asked for");
  EXPECT_NE(not_asked->body.find("albedo, depth, object_id"), std::string::npos) << not_asked->body;
  expect_problem(client_->Get("/v1/jobs/" + id + "/aovs/..%2fresult.png"), 404, std::nullopt, "not a pass");
  expect_problem(client_->Get("/v1/jobs/" + id + "/aovs/preview.png"), 404, std::nullopt, "not a pass either");

  // A job without passes has none to fetch, and keeps its plain EXR.
  const std::string plain = submit(*client_, cornell_job(48, 8));
  ASSERT_TRUE(in_state(wait_for(*client_, plain, [](const json& s) { return in_state(s, "succeeded"); }), "succeeded"));
  EXPECT_EQ(decode(fetch(*client_, "/v1/jobs/" + plain + "/result.exr"), dir_.path() / "p.exr").channels, 3);
  expect_problem(client_->Get("/v1/jobs/" + plain + "/aovs/albedo.png"), 404, std::nullopt, "no passes");
  // And the files on disk are the data directory's: aov.<pass>.png beside the results.
  EXPECT_TRUE(fs::exists(data_ / "jobs" / id / "aov.depth.png"));
  EXPECT_FALSE(fs::exists(data_ / "jobs" / plain / "aov.depth.png"));
}

// Cryptomatte mattes rendered in a worker: the EXR holds the specification's 24 channels beside the beauty, and the
// passes show as PNGs.
TEST_F(DaemonTest, WritesCryptomatteLayersAndTheirLooks) {
  json doc = cornell_job(32, 4);
  doc["render"]["aovs"] = {"crypto_material", "crypto_object"};
  const std::string id = submit(*client_, doc);
  ASSERT_FALSE(id.empty());
  const json done =
      wait_for(*client_, id, [](const json& s) { return in_state(s, "succeeded") || in_state(s, "failed"); });
  ASSERT_TRUE(in_state(done, "succeeded")) << done.dump();
  EXPECT_EQ(done["render"]["aovs"], json({"crypto_object", "crypto_material"}));
  const ImageData exr = decode(fetch(*client_, "/v1/jobs/" + id + "/result.exr"), dir_.path() / "c.exr");
  EXPECT_EQ(exr.channels, 3 + 2 * 12);
  for (const char* pass : {"crypto_object", "crypto_material"}) {
    const ImageData look = decode(fetch(*client_, "/v1/jobs/" + id + "/aovs/" + pass + ".png"), dir_.path() / "c.png");
    EXPECT_EQ(look.width, 32) << pass;
    EXPECT_GT(mean(look), 0.05) << pass;
  }
}

TEST_F(DaemonTest, AnAdaptiveJobEndsWhenEveryPixelHasStopped) {
  // A threshold of 1: no pixel's error (a standard error at most its mean, over the mean's square root below 1) is
  // above it, so every pixel stops at the first decision point, min_spp.
  json doc = cornell_job(32, 64);
  doc["render"]["adaptive_threshold"] = 1;
  doc["render"]["min_spp"] = 4;
  doc["render"]["aovs"] = {"sample_count"};
  const std::string id = submit(*client_, doc);
  ASSERT_FALSE(id.empty());
  const json done =
      wait_for(*client_, id, [](const json& s) { return in_state(s, "succeeded") || in_state(s, "failed"); });
  ASSERT_TRUE(in_state(done, "succeeded")) << done.dump();
  auto e = proto::contract_schemas().validate(done, "job-status.schema.json");
  EXPECT_FALSE(e) << e->pointer << " " << e->message;
  EXPECT_EQ(done["stop_reason"], "adaptive_threshold");
  EXPECT_EQ(done["progress"]["samples_done"], 4);  // the mean over the pixels
  EXPECT_EQ(done["render"]["adaptive_threshold"], 1.0);
  EXPECT_EQ(done["render"]["min_spp"], 4);
  const ImageData exr = decode(fetch(*client_, "/v1/jobs/" + id + "/result.exr"), dir_.path() / "a.exr");
  EXPECT_EQ(exr.channels, 4);
}

TEST_F(DaemonTest, PreviewWhileRunningThenCancel) {
  const std::string id = submit(*client_, long_cornell_job());
  ASSERT_FALSE(id.empty());
  const json running = wait_for(
      *client_, id, [](const json& s) { return in_state(s, "running") && s["progress"]["passes"].get<int>() >= 1; });
  ASSERT_TRUE(in_state(running, "running"));
  EXPECT_GT(running["progress"]["samples_done"].get<int>(), 0);
  EXPECT_TRUE(running["links"].contains("preview"));

  const ImageData preview = decode(fetch(*client_, "/v1/jobs/" + id + "/preview.png"), dir_.path() / "p.png");
  EXPECT_EQ(preview.width, 128);
  EXPECT_GT(mean(preview), 0.01);
  expect_problem(client_->Get("/v1/jobs/" + id + "/result.png"), 409, std::nullopt, "result while running");
  expect_problem(client_->Get("/v1/jobs/" + id + "/result.exr"), 409, std::nullopt, "exr while running");

  auto res = client_->Post("/v1/jobs/" + id + "/cancel");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << res->body;
  const json cancelled = wait_for(
      *client_, id, [](const json& s) { return in_state(s, "cancelled"); }, 10);
  EXPECT_TRUE(in_state(cancelled, "cancelled"));
  EXPECT_EQ(cancelled["stop_reason"], "cancelled");
  // Cancelled after a pass: the image of its last complete pass is its (partial) result.
  const ImageData partial = decode(fetch(*client_, "/v1/jobs/" + id + "/result.png"), dir_.path() / "r.png");
  EXPECT_EQ(partial.width, 128);
  EXPECT_GT(mean(partial), 0.01);

  // Delete removes the job and its files.
  EXPECT_TRUE(fs::exists(data_ / "jobs" / id / "preview.png"));
  res = client_->Delete("/v1/jobs/" + id);
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 204);
  expect_problem(client_->Get("/v1/jobs/" + id), 404, std::nullopt, "deleted job");
  EXPECT_FALSE(fs::exists(data_ / "jobs" / id));
  expect_problem(client_->Delete("/v1/jobs/" + id), 404, std::nullopt, "deleted twice");
}

TEST_F(DaemonTest, CancelsAQueuedJobAndDeletesARunningOne) {
  // Two long jobs fill both slots; the third waits in the queue.
  const std::string a = submit(*client_, long_cornell_job()), b = submit(*client_, long_cornell_job());
  const std::string c = submit(*client_, long_cornell_job());
  wait_for(*client_, b, [](const json& s) { return in_state(s, "running"); });
  EXPECT_TRUE(in_state(get_job(*client_, c), "queued"));
  expect_problem(client_->Get("/v1/jobs/" + c + "/preview.png"), 409, std::nullopt, "preview while queued");
  auto res = client_->Post("/v1/jobs/" + c + "/cancel");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
  EXPECT_TRUE(in_state(json::parse(res->body), "cancelled"));
  // Deleting a running job cancels it; its files go once the render has stopped.
  for (const std::string& id : {a, b}) {
    res = client_->Delete("/v1/jobs/" + id);
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 204);
  }
  for (int i = 0; i < 100 && (fs::exists(data_ / "jobs" / a) || fs::exists(data_ / "jobs" / b)); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_FALSE(fs::exists(data_ / "jobs" / a));
  EXPECT_FALSE(fs::exists(data_ / "jobs" / b));
  EXPECT_EQ(fetch(*client_, "/livez"), R"({"status":"ok"})");
}

struct BadRequest {
  const char* name;
  std::string content_type;
  std::string body;
  int status;
  std::optional<std::string> pointer;
};

json patched(const char* patch) {
  return cornell_job(64, 16).patch(json::parse(patch));
}

std::vector<BadRequest> bad_requests() {
  const std::string json_type = "application/json";
  return {
      {"width 0", json_type, patched(R"([{"op":"replace","path":"/render/width","value":0}])").dump(), 422,
       "/render/width"},
      {"width above the configured max", json_type,
       patched(R"([{"op":"replace","path":"/render/width","value":4096}])").dump(), 422, "/render/width"},
      {"huge width", json_type, patched(R"([{"op":"replace","path":"/render/width","value":1e300}])").dump(), 422,
       "/render/width"},
      {"spp 0", json_type, patched(R"([{"op":"replace","path":"/render/spp","value":0}])").dump(), 422, "/render/spp"},
      {"negative spp", json_type, patched(R"([{"op":"replace","path":"/render/spp","value":-16}])").dump(), 422,
       "/render/spp"},
      {"NaN-like string width", json_type, patched(R"([{"op":"replace","path":"/render/width","value":"NaN"}])").dump(),
       422, "/render/width"},
      {"NaN-like string coordinate", json_type,
       patched(R"([{"op":"replace","path":"/scene/camera/from/1","value":"nan"}])").dump(), 422,
       "/scene/camera/from/1"},
      {"NaN literal", json_type, R"({"kind": "scene", "render": {"width": NaN}})", 400, "/render/width"},
      {"render of the wrong type", json_type, patched(R"([{"op":"replace","path":"/render","value":"fast"}])").dump(),
       422, "/render"},
      {"objects of the wrong type", json_type,
       patched(R"([{"op":"replace","path":"/scene/objects","value":{}}])").dump(), 422, "/scene/objects"},
      {"unknown material name", json_type,
       patched(R"([{"op":"replace","path":"/scene/objects/3/material","value":"purple"}])").dump(), 422,
       "/scene/objects/3/material"},
      {"missing camera", json_type, patched(R"([{"op":"remove","path":"/scene/camera"}])").dump(), 422,
       "/scene/camera"},
      {"bad estimator", json_type, patched(R"([{"op":"replace","path":"/render/estimator","value":"bdpt"}])").dump(),
       422, "/render/estimator"},
      {"bad integrator", json_type,
       patched(R"([{"op":"add","path":"/render/integrator","value":"photon_mapping"}])").dump(), 422,
       "/render/integrator"},
      {"unknown shape", json_type,
       patched(R"([{"op":"replace","path":"/scene/objects/2/shape","value":"teapot"}])").dump(), 422,
       "/scene/objects/2/shape"},
      {"index out of range", json_type,
       patched(R"([{"op":"replace","path":"/scene/objects/6/indices/5","value":99}])").dump(), 422,
       "/scene/objects/6/indices/5"},
      {"parallel rectangle edges", json_type,
       patched(R"([{"op":"replace","path":"/scene/objects/0/edge2","value":[0,0,1]}])").dump(), 422,
       "/scene/objects/0/edge2"},
      {"negative radiance", json_type,
       patched(R"([{"op":"replace","path":"/scene/materials/light/radiance/2","value":-4}])").dump(), 422,
       "/scene/materials/light/radiance/2"},
      {"a film above --max-film-bytes (2048 x 2048 x 680 bytes with the light passes)", json_type,
       patched(R"([{"op":"replace","path":"/render/width","value":2048},
                   {"op":"replace","path":"/render/height","value":2048},
                   {"op":"add","path":"/render/aovs","value":["diffuse_color"]}])")
           .dump(),
       422, "/render/aovs"},
      {"misspelt pass", json_type, patched(R"([{"op":"add","path":"/render/aovs","value":["depth","albdo"]}])").dump(),
       422, "/render/aovs/1"},
      {"pass asked twice", json_type,
       patched(R"([{"op":"add","path":"/render/aovs","value":["depth","depth"]}])").dump(), 422, "/render/aovs/1"},
      {"pass the integrator cannot make", json_type,
       patched(R"([{"op":"add","path":"/render/integrator","value":"light"},
                   {"op":"add","path":"/render/aovs","value":["albedo"]}])")
           .dump(),
       422, "/render/aovs/0"},
      {"adaptive threshold above 1", json_type,
       patched(R"([{"op":"add","path":"/render/adaptive_threshold","value":1.5}])").dump(), 422,
       "/render/adaptive_threshold"},
      {"min_spp above spp", json_type, patched(R"([{"op":"add","path":"/render/min_spp","value":17}])").dump(), 422,
       "/render/min_spp"},
      {"adaptive sampling with bdpt", json_type,
       patched(R"([{"op":"add","path":"/render/integrator","value":"bdpt"},
                   {"op":"add","path":"/render/adaptive_threshold","value":0.01}])")
           .dump(),
       422, "/render/adaptive_threshold"},
      {"unknown kind", json_type, patched(R"([{"op":"replace","path":"/kind","value":"video"}])").dump(), 422, "/kind"},
      {"not JSON at all", json_type, "this is not JSON", 400, ""},
      {"truncated JSON", json_type, cornell_job(64, 16).dump().substr(0, 100), 400, std::nullopt},
      {"empty body", json_type, "", 400, ""},
      {"array instead of object", json_type, "[1, 2, 3]", 422, ""},
      {"deep nesting", json_type, std::string(5000, '[') + std::string(5000, ']'), 422, ""},
      {"wrong content type", "text/plain", cornell_job(64, 16).dump(), 415, std::nullopt},
      {"form content type", "application/x-www-form-urlencoded", "kind=scene", 415, std::nullopt},
      {"oversized body", json_type, std::string(2 << 20, ' '), 413, std::nullopt},
  };
}

TEST_F(DaemonTest, BadDocumentsAreAnsweredWithProblems) {
  const auto cases = bad_requests();
  ASSERT_GE(cases.size(), 15u);
  for (const BadRequest& c : cases) {
    expect_problem(client_->Post("/v1/jobs", c.body, c.content_type), c.status, c.pointer, c.name);
    auto live = client_->Get("/livez");
    ASSERT_TRUE(live) << "the daemon stopped answering after: " << c.name;
    EXPECT_EQ(live->status, 200) << c.name;
  }
  // None of them became a job.
  EXPECT_TRUE(json::parse(fetch(*client_, "/v1/jobs"))["jobs"].empty());
}

TEST_F(DaemonTest, RoutesAndTheContract) {
  expect_problem(client_->Get("/no/such/route"), 404, std::nullopt, "unknown route");
  auto res = client_->Put("/v1/jobs", "{}", "application/json");
  expect_problem(res, 405, std::nullopt, "PUT /v1/jobs");
  if (res) {
    EXPECT_NE(res->get_header_value("Allow").find("POST"), std::string::npos);
  }
  expect_problem(client_->Delete("/livez"), 405, std::nullopt, "DELETE /livez");
  const std::string unknown = "0123456789abcdef0123456789abcdef";
  expect_problem(client_->Get("/v1/jobs/" + unknown), 404, std::nullopt, "unknown id");
  expect_problem(client_->Get("/v1/jobs/" + unknown + "/result.png"), 404, std::nullopt, "unknown id result");
  expect_problem(client_->Get("/v1/jobs/" + unknown + "/preview.png"), 404, std::nullopt, "unknown id preview");
  expect_problem(client_->Post("/v1/jobs/" + unknown + "/cancel"), 404, std::nullopt, "unknown id cancel");
  expect_problem(client_->Get("/v1/jobs/..%2F..%2Fjobs.db"), 404, std::nullopt, "traversal id");
  expect_problem(client_->Get("/v1/jobs/NOT-AN-ID/result.exr"), 404, std::nullopt, "malformed id");
  expect_problem(client_->Get("/v1/jobs?state=done"), 400, std::nullopt, "bad state filter");
  expect_problem(client_->Get("/v1/jobs?limit=0"), 400, std::nullopt, "bad limit");
  expect_problem(client_->Get("/v1/schemas/..%2Fopenapi.json"), 404, std::nullopt, "schema traversal");

  const json ready = json::parse(fetch(*client_, "/readyz"));
  EXPECT_EQ(ready["status"], "ready") << ready.dump();
  EXPECT_EQ(ready["storage"]["min_free_disk_bytes"], 256u << 20) << ready.dump();  // the default --min-free-disk
  EXPECT_EQ(ready["storage"]["below_minimum"], false) << ready.dump();
  EXPECT_EQ(ready["storage"]["job_store_failing"], false) << ready.dump();
  const json openapi = json::parse(fetch(*client_, "/v1/openapi.json"));
  EXPECT_TRUE(openapi["paths"].contains("/v1/jobs/{id}/result.exr"));
  const json job_schema = json::parse(fetch(*client_, "/v1/schemas/job.schema.json"));
  EXPECT_EQ(job_schema["title"], "Job");
  const json materials = json::parse(fetch(*client_, "/v1/materials"));
  EXPECT_FALSE(materials["materials"].empty());
  auto page = client_->Get("/");
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 200);
  EXPECT_NE(page->get_header_value("Content-Type").find("text/html"), std::string::npos);
}

TEST(DaemonRestart, FinishedJobsAndFilesSurviveAndRunningJobsGoBackToTheQueue) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  std::string done_id, long_id, png, exr;
  {
    Daemon daemon(data, kDaemonArgs);
    auto c = daemon.client();
    done_id = submit(*c, cornell_job(32, 4));
    ASSERT_TRUE(in_state(wait_for(*c, done_id, [](const json& s) { return in_state(s, "succeeded"); }), "succeeded"));
    png = fetch(*c, "/v1/jobs/" + done_id + "/result.png");
    exr = fetch(*c, "/v1/jobs/" + done_id + "/result.exr");
    long_id = submit(*c, long_cornell_job());
    wait_for(*c, long_id, [](const json& s) { return in_state(s, "running"); });
    // SIGTERM: stop accepting, cancel the render, put its job back in the queue, exit 0.
    EXPECT_EQ(daemon.stop(SIGTERM), 0) << daemon.log();
  }
  Daemon daemon(data, kDaemonArgs);
  auto c = daemon.client();
  const json done = get_job(*c, done_id);
  EXPECT_TRUE(in_state(done, "succeeded")) << done.dump();
  EXPECT_EQ(fetch(*c, "/v1/jobs/" + done_id + "/result.png"), png);
  EXPECT_EQ(fetch(*c, "/v1/jobs/" + done_id + "/result.exr"), exr);
  const json again = get_job(*c, long_id);
  EXPECT_TRUE(in_state(again, "queued") || in_state(again, "running")) << again.dump();
  auto res = c->Post("/v1/jobs/" + long_id + "/cancel");
  ASSERT_TRUE(res);
  wait_for(
      *c, long_id, [](const json& s) { return in_state(s, "cancelled"); }, 10);
  EXPECT_EQ(daemon.stop(SIGINT), 0);
}

TEST(DaemonRestart, QueuedJobsRunAfterACrash) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  std::vector<std::string> args = kDaemonArgs;
  args[3] = "1";  // --max-jobs 1: the long job holds the only slot
  std::string long_id, queued_id;
  {
    Daemon daemon(data, args);
    auto c = daemon.client();
    long_id = submit(*c, long_cornell_job());
    wait_for(*c, long_id, [](const json& s) { return in_state(s, "running"); });
    json small = cornell_job(32, 4);
    small["priority"] = 5;  // runs first once the daemon is back
    queued_id = submit(*c, small);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    EXPECT_TRUE(in_state(get_job(*c, queued_id), "queued"));
    EXPECT_EQ(daemon.stop(SIGKILL), 128 + SIGKILL);  // no chance to clean up: the store still says "running"
  }
  Daemon daemon(data, args);
  auto c = daemon.client();
  const json done = wait_for(*c, queued_id, [](const json& s) { return in_state(s, "succeeded"); });
  EXPECT_TRUE(in_state(done, "succeeded")) << done.dump();
  const ImageData png = decode(fetch(*c, "/v1/jobs/" + queued_id + "/result.png"), dir.path() / "q.png");
  EXPECT_EQ(png.width, 32);
  // The job the crash interrupted was put back in the queue and runs again.
  const json requeued = wait_for(*c, long_id, [](const json& s) { return in_state(s, "running"); });
  EXPECT_TRUE(in_state(requeued, "running"));
  c->Post("/v1/jobs/" + long_id + "/cancel");
  wait_for(
      *c, long_id, [](const json& s) { return in_state(s, "cancelled"); }, 10);
  EXPECT_EQ(daemon.stop(SIGTERM), 0);
}

// A job whose renderer dies while rendering it (here the whole daemon, killed) is rendered again at the next start,
// up to --crash-retries times; then it fails naming the crashes, and later starts leave it failed: a scene that
// crashes the renderer cannot crash the daemon at every start.
TEST(DaemonRestart, AJobLostMoreOftenThanItsRetriesFailsInsteadOfLooping) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  std::vector<std::string> args = kDaemonArgs;
  args.insert(args.end(), {"--crash-retries", "1"});
  std::string id;
  json last_start;
  for (int start = 0; start < 2; ++start) {  // killed while rendering it, twice
    Daemon daemon(data, args);
    auto c = daemon.client();
    if (id.empty()) id = submit(*c, long_cornell_job());
    // Running under this daemon: the store still says running for the killed one until this start requeues it.
    const json running = wait_for(
        *c, id, [&](const json& s) { return in_state(s, "running") && s.value("started_at", json()) != last_start; });
    ASSERT_TRUE(in_state(running, "running")) << "start " << start << ": " << running.dump();
    last_start = running.value("started_at", json());
    EXPECT_EQ(daemon.stop(SIGKILL), 128 + SIGKILL);
  }
  json finished_at;
  for (int start = 2; start < 4; ++start) {
    Daemon daemon(data, args);
    auto c = daemon.client();
    const json failed = wait_for(*c, id, [](const json& s) { return in_state(s, "failed"); });
    ASSERT_TRUE(in_state(failed, "failed")) << failed.dump();
    EXPECT_NE(failed.value("error", "").find("the renderer stopped 2 times while rendering this job"),
              std::string::npos)
        << failed.dump();
    // Failed at the third start, and left so by the fourth.
    if (start == 2) finished_at = failed.at("finished_at");
    EXPECT_EQ(failed.at("finished_at"), finished_at) << "ended again: " << failed.dump();
    EXPECT_EQ(daemon.stop(SIGTERM), 0);
  }
}

}  // namespace
}  // namespace tessera::server::test
