// Material jobs over HTTP: every model the daemon lists renders on the preview stage; a row of materials renders;
// a parameter out of range is a 422 naming the field; a material job's render passes are layers of its EXR and PNGs;
// a preview samples adaptively and is denoised unless the job says otherwise.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <thread>

#include "renderer/image_io.h"
#include "renderer/render_settings.h"
#include "tests/integration/daemon.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;

json wait_until_done(httplib::Client& c, const std::string& id, double timeout_s = 60) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  json status;
  while (std::chrono::steady_clock::now() < deadline) {
    auto res = c.Get("/v1/jobs/" + id);
    if (res && res->status == 200) {
      status = json::parse(res->body);
      const std::string state = status.value("state", "");
      if (state == "succeeded" || state == "failed" || state == "cancelled") return status;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ADD_FAILURE() << "job " << id << " did not finish; last status " << status.dump();
  return status;
}

class MaterialJobs : public testing::Test {
 protected:
  void SetUp() override {
    daemon_ =
        std::make_unique<Daemon>(dir_.path() / "data", std::vector<std::string>{"--threads", "2", "--max-jobs", "2"});
    client_ = daemon_->client();
  }
  void TearDown() override {
    if (HasFailure() && daemon_) std::fprintf(stderr, "--- tesserad log ---\n%s\n", daemon_->log().c_str());
  }
  // Submits `job` and follows it to its end: its last status (a failure is added where it is not accepted).
  json render(const json& job) {
    auto r = client_->Post("/v1/jobs", job.dump(), "application/json");
    if (!r || r->status != 202) {
      ADD_FAILURE() << "not accepted: " << (r ? r->body : "no answer");
      return json::object();
    }
    return wait_until_done(*client_, json::parse(r->body)["id"]);
  }
  // The result.exr of job `id`, as OpenImageIO reads it.
  ImageData result_exr(const std::string& id) {
    auto exr = client_->Get("/v1/jobs/" + id + "/result.exr");
    if (!exr || exr->status != 200) {
      ADD_FAILURE() << "no result.exr for " << id;
      return {};
    }
    const std::string file = (dir_.path() / (id + ".exr")).string();
    {
      std::ofstream out(file, std::ios::binary);
      out.write(exr->body.data(), static_cast<std::streamsize>(exr->body.size()));
    }
    return read_image(file);
  }
  TempDir dir_;
  std::unique_ptr<Daemon> daemon_;
  std::unique_ptr<httplib::Client> client_;
};

TEST_F(MaterialJobs, EveryListedModelRendersWithItsDefaults) {
  auto res = client_->Get("/v1/materials");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200);
  const json catalogue = json::parse(res->body);
  ASSERT_GE(catalogue["materials"].size(), 15u);
  std::vector<std::pair<std::string, std::string>> jobs;  // (type, id)
  for (const json& model : catalogue["materials"]) {
    const std::string type = model["type"];
    json job = {{"kind", "material"},
                {"material", {{"type", type}}},
                {"render", {{"width", 32}, {"height", 32}, {"spp", 4}}},
                {"outputs", {"png"}}};
    auto r = client_->Post("/v1/jobs", job.dump(), "application/json");
    ASSERT_TRUE(r);
    ASSERT_EQ(r->status, 202) << type << ": " << r->body;
    jobs.emplace_back(type, json::parse(r->body)["id"].get<std::string>());
  }
  for (const auto& [type, id] : jobs) {
    json status = wait_until_done(*client_, id);
    EXPECT_EQ(status.value("state", ""), "succeeded") << type << ": " << status.dump();
    auto png = client_->Get("/v1/jobs/" + id + "/result.png");
    ASSERT_TRUE(png);
    EXPECT_EQ(png->status, 200) << type;
    EXPECT_EQ(png->body.substr(1, 3), "PNG") << type;
  }
}

TEST_F(MaterialJobs, ARowOfMaterialsRendersAndBadParametersAreNamed) {
  json row = {
      {"kind", "material"},
      {"materials", {{{"type", "lambert"}}, {{"type", "conductor"}, {"metal", "copper"}}, {{"type", "dielectric"}}}},
      {"render", {{"width", 48}, {"height", 16}, {"spp", 2}}}};
  auto r = client_->Post("/v1/jobs", row.dump(), "application/json");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 202) << r->body;
  EXPECT_EQ(wait_until_done(*client_, json::parse(r->body)["id"]).value("state", ""), "succeeded");

  auto expect_422 = [&](const json& doc, const std::string& pointer) {
    auto res = client_->Post("/v1/jobs", doc.dump(), "application/json");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 422) << doc.dump() << ": " << res->body;
    json body = json::parse(res->body, nullptr, false);
    EXPECT_EQ(body.value("pointer", std::string()), pointer) << res->body;
  };
  json bad = {{"kind", "material"}, {"material", {{"type", "lambert"}, {"albedo", 1.5}}}};
  expect_422(bad, "/material/albedo");
  json bad_row = row;
  bad_row["materials"][1]["roughness"] = -0.5;
  expect_422(bad_row, "/materials/1/roughness");
  json both = {{"kind", "material"}, {"material", {{"type", "lambert"}}}, {"materials", {{{"type", "lambert"}}}}};
  auto res = client_->Post("/v1/jobs", both.dump(), "application/json");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 422) << "material and materials together: " << res->body;
  // The daemon is still alive.
  auto live = client_->Get("/livez");
  ASSERT_TRUE(live);
  EXPECT_EQ(live->status, 200);
}

// Material jobs take render passes as scene jobs do (the same render settings): albedo and normal are 3 + 3 channels
// beside the beauty's 3, and each pass shows alone as PNG.
TEST_F(MaterialJobs, RenderPassesAreLayersOfTheExrAndPngs) {
  json job = {{"kind", "material"},
              {"material", {{"type", "conductor"}, {"metal", "gold"}, {"roughness", 0.3}}},
              {"render", {{"width", 32}, {"height", 24}, {"spp", 4}, {"aovs", {"albedo", "normal"}}}}};
  const json status = render(job);
  ASSERT_EQ(status.value("state", ""), "succeeded") << status.dump();
  EXPECT_EQ(status["render"]["aovs"], json({"albedo", "normal"}));
  const std::string id = status["id"];

  const ImageData image = result_exr(id);
  EXPECT_EQ(image.width, 32);
  EXPECT_EQ(image.channels, 12);  // R, G, B, the two passes, and the preview's denoiser's noisy.R, .G, .B

  for (const std::string pass : {"albedo", "normal"}) {
    auto png = client_->Get("/v1/jobs/" + id + "/aovs/" + pass + ".png");
    ASSERT_TRUE(png);
    EXPECT_EQ(png->status, 200) << pass << ": " << png->body;
    EXPECT_EQ(png->body.substr(1, 3), "PNG") << pass;
  }
}

// A material preview samples adaptively and is denoised unless its document says otherwise: without those settings the
// job stops by its threshold at a mean below spp, and its EXR holds the rendered image as noisy.R, .G, .B beside the
// denoised one; with adaptive_threshold 0 and denoise none every pixel gets spp samples and the EXR holds R, G, B.
TEST_F(MaterialJobs, APreviewIsAdaptiveAndDenoisedUnlessTheJobSaysOtherwise) {
  const json size = {{"width", 24}, {"height", 24}, {"spp", 256}};
  json off = size;
  off["adaptive_threshold"] = 0;
  off["denoise"] = "none";
  struct Case {
    json render;
    std::string stop_reason, denoise;
    int channels;
  };
  for (const Case& c : {Case{size, "adaptive_threshold", "regression", 6}, Case{off, "samples", "none", 3}}) {
    const json job = {{"kind", "material"}, {"material", {{"type", "lambert"}}}, {"render", c.render}};
    const json status = render(job);
    ASSERT_EQ(status.value("state", ""), "succeeded") << status.dump();
    EXPECT_EQ(status["stop_reason"], c.stop_reason) << status.dump();
    EXPECT_EQ(status["render"].value("denoise", "none"), c.denoise);  // "none" is left out, as a default
    const json& p = status["progress"];
    if (c.stop_reason == "samples") {
      EXPECT_EQ(status["render"].value("adaptive_threshold", 0.0), 0.0);
      EXPECT_EQ(p["samples_done"], 256);
    } else {
      EXPECT_FLOAT_EQ(status["render"]["adaptive_threshold"].get<double>(), kPreviewAdaptiveThreshold);
      EXPECT_LT(p["samples_done"].get<double>(), 256) << p.dump();
    }
    EXPECT_EQ(result_exr(status["id"]).channels, c.channels) << c.render.dump();
  }
}

}  // namespace
}  // namespace tessera::server::test
