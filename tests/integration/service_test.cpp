// Assets and the job service over real HTTP: uploads and hostile uploads, multipart jobs,
// Server-Sent Events with replay, priorities and pause/resume/requeue, idempotency, ETags, pagination, tokens and
// CORS, limits, metrics checked by promtool, SIGTERM drain, a SIGKILL crash loop whose resumed renders must be
// bit-identical to uninterrupted ones, and bounded loopback load. Correctness only: no timing assertions.
#include <signal.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <chrono>
#include <cstring>
#include <fstream>
#include <functional>
#include <random>
#include <set>
#include <string_view>
#include <thread>

#include "proto/contract.h"
#include "renderer/image_io.h"
#include "renderer/output.h"
#include "tests/integration/daemon.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

std::vector<std::string> args(std::vector<std::string> extra = {}) {
  std::vector<std::string> a = {"--threads",     "2",    "--max-jobs",  "2",     "--max-width",      "2048",
                                "--max-height",  "2048", "--log-level", "debug", "--max-body-bytes", "8388608",
                                "--keepalive-s", "1"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

httplib::Headers bearer(const std::string& token) {
  return {{"Authorization", "Bearer " + token}};
}

std::string submit(httplib::Client& c, const json& doc, const httplib::Headers& h = {}) {
  auto res = c.Post("/v1/jobs", h, doc.dump(), "application/json");
  if (!res || res->status != 202) {
    ADD_FAILURE() << "submit: " << (res ? std::to_string(res->status) + " " + res->body : "no answer");
    return "";
  }
  return json::parse(res->body).value("id", "");
}

json get_job(httplib::Client& c, const std::string& id, const httplib::Headers& h = {}) {
  auto res = c.Get("/v1/jobs/" + id, h);
  if (!res || res->status != 200) return json();
  return json::parse(res->body);
}

json wait_for(httplib::Client& c, const std::string& id, const std::function<bool(const json&)>& done,
              double timeout_s = 60, const httplib::Headers& h = {}) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  json s;
  while (std::chrono::steady_clock::now() < deadline) {
    s = get_job(c, id, h);
    if (!s.is_null() && done(s)) return s;
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
  }
  ADD_FAILURE() << "timed out waiting for " << id << ": " << s.dump();
  return s;
}

auto in_state(const char* state) {
  return [state](const json& s) { return s.value("state", "") == state; };
}
bool ended(const json& s) {
  const std::string st = s.value("state", "");
  return st == "succeeded" || st == "failed" || st == "cancelled";
}

void expect_status(const httplib::Result& res, int status, const std::string& what) {
  ASSERT_TRUE(res) << what << ": no answer";
  EXPECT_EQ(res->status, status) << what << ": " << res->body;
  if (status >= 400) {
    EXPECT_EQ(res->get_header_value("Content-Type"), "application/problem+json") << what;
  }
}

void expect_alive(httplib::Client& c, const std::string& after) {
  auto live = c.Get("/livez");
  ASSERT_TRUE(live) << "the daemon stopped answering after: " << after;
  EXPECT_EQ(live->status, 200) << after;
}

// ---- glTF fixtures -------------------------------------------------------------------------------------------

// One triangle facing +z: positions in a .bin (36 bytes), lit by a point light.
json triangle_gltf(const std::string& uri, int byte_length = 36, int count = 3) {
  return {{"asset", {{"version", "2.0"}}},
          {"scene", 0},
          {"scenes", {{{"nodes", {0, 1}}}}},
          {"nodes",
           {{{"mesh", 0}}, {{"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}, {"translation", {0, 0, 2}}}}},
          {"extensionsUsed", {"KHR_lights_punctual"}},
          {"extensions", {{"KHR_lights_punctual", {{"lights", {{{"type", "point"}, {"intensity", 5}}}}}}}},
          {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}}}}}}},
          {"accessors",
           {{{"bufferView", 0},
             {"componentType", 5126},
             {"count", count},
             {"type", "VEC3"},
             {"min", {-1, -1, 0}},
             {"max", {1, 1, 0}}}}},
          {"bufferViews", {{{"buffer", 0}, {"byteLength", 36}}}},
          {"buffers", {{{"uri", uri}, {"byteLength", byte_length}}}}};
}

std::string triangle_bin() {
  const float p[9] = {-1, -1, 0, 1, -1, 0, 0, 1, 0};
  return std::string(reinterpret_cast<const char*>(p), sizeof p);
}

// A .glb of `gltf` with `bin` as its BIN chunk.
std::string make_glb(const json& gltf, const std::string& bin) {
  std::string j = gltf.dump();
  while (j.size() % 4) j += ' ';
  std::string b = bin;
  while (b.size() % 4) b += '\0';
  auto u32 = [](uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
  std::string out = "glTF" + u32(2) + u32(static_cast<uint32_t>(12 + 8 + j.size() + (b.empty() ? 0 : 8 + b.size())));
  out += u32(static_cast<uint32_t>(j.size())) + u32(0x4E4F534A) + j;
  if (!b.empty()) out += u32(static_cast<uint32_t>(b.size())) + u32(0x004E4942) + b;
  return out;
}

// The sample assets of examples/.
std::vector<fs::path> example_glbs() {
  std::vector<fs::path> out;
  const fs::path scenes = fs::path(TESSERA_SOURCE_DIR) / "examples";
  std::error_code ec;
  for (const auto& dir : fs::directory_iterator(scenes, ec))
    for (const auto& f : fs::directory_iterator(dir.path(), ec))
      if (f.path().extension() == ".glb") out.push_back(f.path());
  std::sort(out.begin(), out.end());
  return out;
}

class ServiceTest : public testing::Test {
 protected:
  void start(const std::vector<std::string>& a = args()) {
    data_ = dir_.path() / "data";
    daemon_ = std::make_unique<Daemon>(data_, a);
    client_ = daemon_->client();
  }
  void TearDown() override {
    if (HasFailure() && daemon_)
      std::fprintf(stderr, "--- tesserad log (tail) ---\n%s\n", tail(daemon_->log()).c_str());
  }
  static std::string tail(const std::string& s) { return s.size() > 20000 ? s.substr(s.size() - 20000) : s; }
  TempDir dir_;
  fs::path data_;
  std::unique_ptr<Daemon> daemon_;
  std::unique_ptr<httplib::Client> client_;
};

// ---- assets --------------------------------------------------------------------------------------------------

TEST_F(ServiceTest, UploadsTheSampleAssetsAndRendersThem) {
  const auto glbs = example_glbs();
  ASSERT_GE(glbs.size(), 3u) << "examples/*/*.glb";
  start();
  std::vector<std::string> jobs;
  for (const fs::path& glb : glbs) {
    const std::string bytes = read_text(glb);
    auto res = client_->Post("/v1/assets?name=" + glb.filename().string(), bytes, "model/gltf-binary");
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 201) << glb << ": " << res->body;
    const json asset = json::parse(res->body);
    EXPECT_EQ(asset["kind"], "gltf");
    EXPECT_EQ(asset["bytes"], bytes.size());
    EXPECT_TRUE(fs::exists(data_ / "assets" / asset["id"].get<std::string>() / glb.filename()));
    // The same content again: the same id, 200.
    auto again = client_->Post("/v1/assets?name=" + glb.filename().string(), bytes, "model/gltf-binary");
    ASSERT_TRUE(again);
    EXPECT_EQ(again->status, 200);
    EXPECT_EQ(json::parse(again->body)["id"], asset["id"]);
    EXPECT_EQ(json::parse(client_->Get("/v1/assets/" + asset["id"].get<std::string>())->body)["main"],
              glb.filename().string());
    jobs.push_back(submit(*client_, {{"kind", "scene"},
                                     {"scene", {{"gltf", asset["id"]}}},
                                     {"render", {{"width", 48}, {"height", 32}, {"spp", 2}}}}));
  }
  for (const std::string& id : jobs) {
    const json done = wait_for(*client_, id, ended, 120);
    EXPECT_EQ(done.value("state", ""), "succeeded") << done.dump();
    EXPECT_EQ(client_->Get("/v1/jobs/" + id + "/result.png")->status, 200);
  }
  // An unknown asset id is refused at submission, naming the field.
  auto res = client_->Post("/v1/jobs", json{{"kind", "scene"}, {"scene", {{"gltf", std::string(64, 'a')}}}}.dump(),
                           "application/json");
  expect_status(res, 422, "unknown asset");
  EXPECT_EQ(json::parse(res->body)["pointer"], "/scene/gltf");
}

// A frame range the daemon cannot render is refused naming /render/frames: an end before its start, a step of 0,
// more frames than --max-frames; a range of one frame is the still at its time.
TEST_F(ServiceTest, ABadFrameRangeIsRefusedNamingTheField) {
  std::vector<std::string> a = args();
  a.insert(a.end(), {"--max-frames", "100"});
  start(a);
  const std::string bytes = read_text(fs::path(TESSERA_SOURCE_DIR) / "examples/spinning_cube/SpinningCube.glb");
  auto up = client_->Post("/v1/assets?name=SpinningCube.glb", bytes, "model/gltf-binary");
  ASSERT_TRUE(up);
  ASSERT_EQ(up->status, 201) << up->body;
  const std::string asset = json::parse(up->body)["id"];
  auto job = [&](const json& frames) {
    return json{{"kind", "scene"},
                {"scene", {{"gltf", asset}}},
                {"render", {{"width", 32}, {"height", 18}, {"spp", 1}, {"frames", frames}}}};
  };
  for (const json& bad : {json{{"start", 5}, {"end", 4}}, json{{"start", 1}, {"end", 4}, {"step", 0}},
                          json{{"start", 1}, {"end", 101}}}) {
    auto res = client_->Post("/v1/jobs", job(bad).dump(), "application/json");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 422) << bad.dump() << ": " << res->body;
    EXPECT_EQ(res->get_header_value("Content-Type"), "application/problem+json");
    EXPECT_EQ(json::parse(res->body).value("pointer", "").rfind("/render/frames", 0), 0u) << res->body;
  }
  // A range within the limit is taken.
  auto taken = client_->Post("/v1/jobs", job({{"start", 1}, {"end", 100}}).dump(), "application/json");
  ASSERT_TRUE(taken);
  EXPECT_EQ(taken->status, 202) << taken->body;
  client_->Delete("/v1/jobs/" + json::parse(taken->body).value("id", ""));
  // One frame: accepted, rendered as the still at 12 / 24 s, pixel for pixel.
  const std::string id = submit(*client_, job({{"start", 12}, {"end", 12}}));
  json still_doc = job(nullptr);
  still_doc["render"].erase("frames");
  still_doc["scene"]["time"] = 0.5;
  const std::string still = submit(*client_, still_doc);
  const json done = wait_for(*client_, id, ended, 120);
  EXPECT_EQ(done.value("state", ""), "succeeded") << done.dump();
  EXPECT_EQ(done["render"]["frames"], (json{{"start", 12}, {"end", 12}, {"step", 1}, {"chunk", 1}})) << done.dump();
  EXPECT_EQ(wait_for(*client_, still, ended, 120).value("state", ""), "succeeded");
  const std::string frame_exr = client_->Get("/v1/jobs/" + id + "/result.exr")->body,
                    still_exr = client_->Get("/v1/jobs/" + still + "/result.exr")->body;
  EXPECT_FALSE(frame_exr.empty());
  EXPECT_TRUE(frame_exr == still_exr) << "frame 12 of 12-12 is not the still at 0.5 s";
}

TEST_F(ServiceTest, MultipartJobWithGltfAndBin) {
  start();
  httplib::MultipartFormDataItems items = {
      {"job",
       json{{"kind", "scene"},
            {"scene", {{"gltf", "tri.gltf"}}},
            {"render", {{"width", 24}, {"height", 24}, {"spp", 2}}}}
           .dump(),
       "", "application/json"},
      {"file", triangle_gltf("tri.bin").dump(), "tri.gltf", "model/gltf+json"},
      {"file", triangle_bin(), "tri.bin", "application/octet-stream"},
  };
  auto res = client_->Post("/v1/jobs", items);
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 202) << res->body;
  const std::string id = json::parse(res->body)["id"];
  EXPECT_EQ(wait_for(*client_, id, ended).value("state", ""), "succeeded");
  // A job is called by the glTF file it renders, as uploaded (its document gives no name).
  EXPECT_EQ(get_job(*client_, id).value("name", ""), "tri.gltf");
  // Its document, as accepted, names the upload by its asset id: submitted again, it renders the same files.
  auto document = client_->Get("/v1/jobs/" + id + "/document");
  ASSERT_TRUE(document);
  ASSERT_EQ(document->status, 200) << document->body;
  const json accepted = json::parse(document->body);
  const std::string asset = accepted["scene"].value("gltf", "");
  EXPECT_EQ(asset.size(), 64u) << accepted.dump();
  EXPECT_EQ(accepted["render"], json::parse(items[0].content)["render"]);
  const std::string again = submit(*client_, accepted);
  EXPECT_EQ(wait_for(*client_, again, ended).value("state", ""), "succeeded");
  // The files became one asset; uploading them again as an asset gives its id.
  httplib::MultipartFormDataItems files = {items[1], items[2]};
  res = client_->Post("/v1/assets", files);
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(json::parse(res->body)["files"], json({"tri.bin", "tri.gltf"}));
}

// Uploads and submissions check a job's images from their headers, so they are answered at once: an image whose
// header does not open is refused (422, naming the file and the image), one whose pixels do not decode is accepted
// and fails the job when it starts, naming the image; the daemon goes on.
TEST_F(ServiceTest, ImagesAreCheckedByTheirHeadersAtSubmissionAndByTheirPixelsAtRender) {
  start();
  std::string png = tessera::encode_image(
      tessera::Image{
          8, 8, {tessera::ImageLayer{"", {"R", "G", "B"}, std::vector<float>(8 * 8 * 3, 0.5f), false, false}}, {}},
      tessera::ImageFormat::kPng, tessera::EncodeOptions{});
  const auto idat = std::search(png.begin(), png.end(), std::begin("IDAT"), std::begin("IDAT") + 4);
  ASSERT_LT(idat - png.begin() + 12, static_cast<std::ptrdiff_t>(png.size()));
  for (auto it = idat + 4; it < idat + 12; ++it) *it ^= 0x5a;  // the compressed pixels, not the header
  json gltf = triangle_gltf("tri.bin");
  gltf["images"] = {{{"uri", "tex.png"}}};
  gltf["textures"] = {{{"source", 0}}};
  gltf["materials"] = {{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}};
  gltf["meshes"][0]["primitives"][0]["material"] = 0;
  auto submit_with = [&](const std::string& image) {
    httplib::MultipartFormDataItems items = {{"job",
                                              json{{"kind", "scene"},
                                                   {"scene", {{"gltf", "tri.gltf"}}},
                                                   {"render", {{"width", 16}, {"height", 16}, {"spp", 1}}}}
                                                  .dump(),
                                              "", "application/json"},
                                             {"file", gltf.dump(), "tri.gltf", "model/gltf+json"},
                                             {"file", triangle_bin(), "tri.bin", "application/octet-stream"},
                                             {"file", image, "tex.png", "image/png"}};
    return client_->Post("/v1/jobs", items);
  };

  auto res = submit_with("not an image at all");
  expect_status(res, 422, "an image that does not open");
  EXPECT_NE(json::parse(res->body)
                .value("detail", "")
                .find("tri.gltf: the glTF asset is invalid: image \"tex.png\" cannot be decoded"),
            std::string::npos)
      << res->body;

  res = submit_with(std::string(png.begin(), png.end()));
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 202) << res->body;
  const std::string failed = json::parse(res->body)["id"];
  const json done = wait_for(*client_, failed, ended);
  EXPECT_EQ(done.value("state", ""), "failed") << done.dump();
  // The image is named by its file, not its index.
  EXPECT_NE(done.value("error", "").find("image \"tex.png\" cannot be decoded"), std::string::npos) << done.dump();
  // Its input is at fault: the same document would fail the same way, so it is not offered a requeue, and one asked
  // for is refused with the reason.
  EXPECT_EQ(done["actions"], json({"delete"})) << done.dump();
  EXPECT_FALSE(done["links"].contains("requeue")) << done.dump();
  res = client_->Post("/v1/jobs/" + failed + "/requeue");
  expect_status(res, 409, "requeue a job that failed on its input");
  EXPECT_NE(res->body.find("failed on its input"), std::string::npos) << res->body;
  EXPECT_EQ(get_job(*client_, failed).value("state", ""), "failed");
  // Its log says why.
  auto log = client_->Get("/v1/jobs/" + failed + "/log");
  ASSERT_TRUE(log);
  EXPECT_NE(log->body.find("failed: "), std::string::npos) << log->body;
  EXPECT_NE(log->body.find("image \"tex.png\" cannot be decoded"), std::string::npos) << log->body;
  EXPECT_NE(log->body.find("(its input is at fault"), std::string::npos) << log->body;
  EXPECT_EQ(client_->Get("/livez")->status, 200);
}

// A job cancelled after a pass keeps the image of its last complete pass as its results, whether it was rendering
// or paused; one cancelled before a pass has none, and says so.
TEST_F(ServiceTest, ACancelledJobKeepsTheImageOfItsLastPass) {
  start(args({"--max-jobs", "1"}));
  const auto png_size = [](const std::string& png) {
    // The IHDR chunk: width and height, big-endian, at bytes 16 and 20.
    auto be32 = [&](size_t at) {
      return (static_cast<uint32_t>(static_cast<unsigned char>(png[at])) << 24) |
             (static_cast<uint32_t>(static_cast<unsigned char>(png[at + 1])) << 16) |
             (static_cast<uint32_t>(static_cast<unsigned char>(png[at + 2])) << 8) |
             static_cast<uint32_t>(static_cast<unsigned char>(png[at + 3]));
    };
    return png.size() > 24 && png.compare(1, 3, "PNG") == 0 ? std::make_pair(be32(16), be32(20))
                                                            : std::make_pair(0u, 0u);
  };
  const std::string running = submit(*client_, long_cornell_job());
  wait_for(*client_, running, [](const json& s) { return s["progress"]["passes"].get<int>() >= 2; });
  const std::string queued = submit(*client_, long_cornell_job());
  expect_status(client_->Post("/v1/jobs/" + queued + "/cancel"), 200, "cancel a queued job");
  expect_status(client_->Get("/v1/jobs/" + queued + "/result.png"), 404, "the results of a job cancelled unstarted");
  EXPECT_NE(client_->Get("/v1/jobs/" + queued + "/result.png")->body.find("cancelled before it finished a pass"),
            std::string::npos);
  EXPECT_FALSE(get_job(*client_, queued)["links"].contains("result_png"));

  client_->Post("/v1/jobs/" + running + "/cancel");
  const json cancelled = wait_for(*client_, running, in_state("cancelled"));
  EXPECT_EQ(cancelled["links"].value("result_png", ""), "/v1/jobs/" + running + "/result.png") << cancelled.dump();
  EXPECT_EQ(cancelled["links"].value("result_exr", ""), "/v1/jobs/" + running + "/result.exr") << cancelled.dump();
  auto png = client_->Get("/v1/jobs/" + running + "/result.png");
  ASSERT_TRUE(png);
  ASSERT_EQ(png->status, 200) << png->body;
  EXPECT_EQ(png_size(png->body), std::make_pair(128u, 128u));
  auto exr = client_->Get("/v1/jobs/" + running + "/result.exr");
  ASSERT_TRUE(exr);
  ASSERT_EQ(exr->status, 200) << exr->body;
  EXPECT_EQ(exr->body.substr(0, 4), std::string("\x76\x2f\x31\x01", 4));  // the OpenEXR magic number
  EXPECT_NE(client_->Get("/v1/jobs/" + running + "/log")->body.find("kept what it rendered"), std::string::npos);

  // Paused after a pass, then cancelled: its checkpoint becomes its results.
  const std::string paused = submit(*client_, long_cornell_job());
  wait_for(*client_, paused, [](const json& s) { return s["progress"]["passes"].get<int>() >= 1; });
  client_->Post("/v1/jobs/" + paused + "/pause");
  wait_for(*client_, paused, in_state("paused"));
  expect_status(client_->Post("/v1/jobs/" + paused + "/cancel"), 200, "cancel a paused job");
  EXPECT_TRUE(get_job(*client_, paused)["links"].contains("result_png"));
  auto paused_png = client_->Get("/v1/jobs/" + paused + "/result.png");
  ASSERT_TRUE(paused_png);
  EXPECT_EQ(paused_png->status, 200) << paused_png->body;
  EXPECT_EQ(png_size(paused_png->body), std::make_pair(128u, 128u));
  // A requeue starts over: the partial results go.
  auto requeued = client_->Post("/v1/jobs/" + paused + "/requeue");  // 202 when it starts at once
  ASSERT_TRUE(requeued && (requeued->status == 200 || requeued->status == 202));
  EXPECT_FALSE(fs::exists(data_ / "jobs" / paused / "result.png"));
  client_->Post("/v1/jobs/" + paused + "/cancel");
}

// A job's log tells what its renders did: loading, each pass, how and why it ended, the client's actions; empty
// before it starts; it goes with the job.
TEST_F(ServiceTest, AJobsLogTellsWhatItsRendersDid) {
  start(args({"--max-jobs", "1"}));
  const std::string blocker = submit(*client_, long_cornell_job());
  const std::string done = submit(*client_, cornell_job(16, 4));
  auto log_of = [&](const std::string& id) {
    auto res = client_->Get("/v1/jobs/" + id + "/log");
    EXPECT_TRUE(res && res->status == 200) << (res ? res->body : "no answer");
    if (res) {
      EXPECT_EQ(res->get_header_value("Content-Type"), "text/plain; charset=utf-8");
    }
    return res ? res->body : "";
  };
  EXPECT_EQ(log_of(done), "");  // queued behind the blocker: nothing yet
  wait_for(*client_, blocker, [](const json& s) { return s["progress"]["passes"].get<int>() >= 1; });
  auto cancel = client_->Post("/v1/jobs/" + blocker + "/cancel");
  ASSERT_TRUE(cancel && (cancel->status == 202 || cancel->status == 200)) << (cancel ? cancel->body : "no answer");
  EXPECT_EQ(wait_for(*client_, done, ended).value("state", ""), "succeeded");
  const std::string text = log_of(done);
  for (const char* line :
       {"Z  loading the scene\n", "Z  scene loaded in ", "Z  rendering 16x16, 4 spp, integrator path",
        "Z  pass 1: ", "/4 spp, ", "Z  succeeded: its samples-per-pixel budget was reached after ", "4 spp in ",
        "; wrote result.png result.exr\n"})
    EXPECT_NE(text.find(line), std::string::npos) << line << " in:\n" << text;
  EXPECT_EQ(text.rfind("20", 0), 0u) << text;  // every line starts with its time
  const std::string cancelled = log_of(blocker);
  EXPECT_NE(cancelled.find("pass 1: "), std::string::npos) << cancelled;
  EXPECT_NE(cancelled.find("cancelled by a client at "), std::string::npos) << cancelled;
  // 200, or 202 when the requeued job was claimed at once and is starting.
  auto requeued = client_->Post("/v1/jobs/" + blocker + "/requeue");
  ASSERT_TRUE(requeued && (requeued->status == 200 || requeued->status == 202));
  EXPECT_NE(log_of(blocker).find("requeued by a client"), std::string::npos);
  client_->Post("/v1/jobs/" + blocker + "/cancel");
  expect_status(client_->Delete("/v1/jobs/" + done), 204, "delete");
  expect_status(client_->Get("/v1/jobs/" + done + "/log"), 404, "the log of a deleted job");
}

// A job has a name: the document's, else the glTF file it renders, its materials' types or its kind; shown in its
// status and the job list, and checked like every field of the document.
TEST_F(ServiceTest, JobsAreCalledByTheirNames) {
  start();
  const json render = {{"width", 8}, {"height", 8}, {"spp", 1}};
  const std::string named = submit(*client_, {{"kind", "material"},
                                              {"name", "Copper, rough"},
                                              {"material", {{"type", "conductor"}, {"metal", "copper"}}},
                                              {"render", render}});
  const std::string one =
      submit(*client_, {{"kind", "material"}, {"material", {{"type", "lambert"}}}, {"render", render}});
  const std::string two =
      submit(*client_,
             {{"kind", "material"}, {"materials", {{{"type", "lambert"}}, {{"type", "plastic"}}}}, {"render", render}});
  json unnamed = cornell_job(8, 1);
  unnamed.erase("name");  // proto/examples/cornell.json is named
  const std::string cornell = submit(*client_, unnamed);
  EXPECT_EQ(get_job(*client_, named).value("name", ""), "Copper, rough");
  EXPECT_EQ(get_job(*client_, one).value("name", ""), "lambert");
  EXPECT_EQ(get_job(*client_, two).value("name", ""), "lambert, plastic");
  EXPECT_EQ(get_job(*client_, cornell).value("name", ""), "scene");
  auto list = client_->Get("/v1/jobs");
  ASSERT_TRUE(list);
  std::set<std::string> names;
  const json jobs = json::parse(list->body)["jobs"];
  for (const json& j : jobs) names.insert(j.value("name", ""));
  EXPECT_EQ(names, (std::set<std::string>{"Copper, rough", "lambert", "lambert, plastic", "scene"}));
  for (const json& bad : {json(""), json("tab\there"), json(std::string(201, 'x')), json(7)}) {
    auto res =
        client_->Post("/v1/jobs", json{{"kind", "material"}, {"name", bad}, {"material", {{"type", "lambert"}}}}.dump(),
                      "application/json");
    expect_status(res, 422, "name " + bad.dump());
    EXPECT_EQ(json::parse(res->body).value("pointer", ""), "/name") << res->body;
  }
}

TEST_F(ServiceTest, HostileUploadsAreRefusedAndTheDaemonLives) {
  start();
  struct Case {
    std::string name;
    httplib::MultipartFormDataItems files;
    int status;
    std::string mentions;
  };
  auto gltf_with = [](const std::string& uri) {
    return httplib::MultipartFormDataItems{{"f", triangle_gltf(uri).dump(), "a.gltf", ""},
                                           {"f", triangle_bin(), "a.bin", ""}};
  };
  const std::string good_glb =
      make_glb(triangle_gltf("").patch(json::parse(R"([{"op":"remove","path":"/buffers/0/uri"}])")), triangle_bin());
  std::vector<Case> cases = {
      {"dot-dot uri", gltf_with("../a.bin"), 422, "../a.bin"},
      {"absolute uri", gltf_with("/etc/passwd"), 422, "/etc/passwd"},
      {"http uri", gltf_with("http://example.com/a.bin"), 422, "http://example.com/a.bin"},
      {"file uri", gltf_with("file:///etc/passwd"), 422, "file:///etc/passwd"},
      {"backslash uri", gltf_with("..\\\\a.bin"), 422, "a.bin"},
      {"uri naming no upload", gltf_with("other.bin"), 422, "other.bin"},
      {"dot-dot file name", {{"f", triangle_gltf("a.bin").dump(), "../a.gltf", ""}}, 422, "is refused"},
      {"hidden file name", {{"f", triangle_gltf("a.bin").dump(), ".a.gltf", ""}}, 422, "is refused"},
      {"bad JSON", {{"f", "{not json", "a.gltf", ""}}, 422, "does not parse"},
      {"buffer shorter than declared",
       {{"f", triangle_gltf("a.bin", 4000).dump(), "a.gltf", ""}, {"f", triangle_bin(), "a.bin", ""}},
       422,
       "4000"},
      {"accessor out of bounds",
       {{"f", triangle_gltf("a.bin", 36, 300).dump(), "a.gltf", ""}, {"f", triangle_bin(), "a.bin", ""}},
       422,
       "accessor"},
      {"truncated glb", {{"f", good_glb.substr(0, good_glb.size() - 10), "a.glb", ""}}, 422, "a.glb"},
      {"wrong magic", {{"f", "glTX" + good_glb.substr(4), "a.glb", ""}}, 422, "magic"},
      {"bad JSON chunk", {{"f", make_glb(json("{"), "").replace(20, 3, "{{{"), "a.glb", ""}}, 422, "a.glb"},
      {"two scenes", {{"f", good_glb, "a.glb", ""}, {"f", good_glb, "b.glb", ""}}, 422, "one .glb"},
      {"not an asset", {{"f", "hello", "a.txt", ""}}, 422, "one .glb"},
  };
  for (const Case& c : cases) {
    auto res = client_->Post("/v1/assets", c.files);
    expect_status(res, c.status, c.name);
    if (res) {
      EXPECT_NE(res->body.find(c.mentions), std::string::npos) << c.name << ": " << res->body;
    }
    expect_alive(*client_, c.name);
  }
  // A type it does not take is told those it does: each of the table's and multipart's.
  auto wrong_type = client_->Post("/v1/assets", "x", "text/plain");
  expect_status(wrong_type, 415, "wrong content type");
  if (wrong_type) {
    const std::string detail = json::parse(wrong_type->body).value("detail", "");
    for (const char* type :
         {"application/octet-stream (with ?name=file.ext)", "model/gltf-binary", "model/gltf+json",
          "image/vnd.radiance", "image/x-exr", "image/aces", "multipart/form-data", "\"text/plain\""})
      EXPECT_NE(detail.find(type), std::string::npos) << type << " is not in: " << detail;
  }
  expect_status(client_->Post("/v1/assets?name=x.hdr", good_glb, "model/gltf-binary"), 422, "name vs type");
  expect_status(client_->Post("/v1/assets?name=a.glb", std::string(9 << 20, 'x'), "model/gltf-binary"), 413, "big");
  // A good one goes through; nothing of the refused ones was stored.
  auto ok = client_->Post("/v1/assets?name=tri.glb", good_glb, "model/gltf-binary");
  expect_status(ok, 201, "good glb");
  size_t stored = 0;
  for (const auto& e : fs::directory_iterator(data_ / "assets")) stored += e.path().filename().string()[0] != '.';
  EXPECT_EQ(stored, 1u);
}

// ---- live progress -------------------------------------------------------------------------------------------

struct SseEvent {
  uint64_t id = 0;
  std::string type, data;
};

// Reads an event stream until it ends (or `stop` says so); `headers` may carry Last-Event-ID.
std::vector<SseEvent> read_events(int port, const std::string& path, const httplib::Headers& headers = {},
                                  const std::function<bool(const std::vector<SseEvent>&)>& stop = {}) {
  httplib::Client c("127.0.0.1", port);
  c.set_read_timeout(60);
  std::vector<SseEvent> events;
  std::string buffer;
  c.Get(path, headers, [&](const char* data, size_t n) {
    buffer.append(data, n);
    size_t end;
    while ((end = buffer.find("\n\n")) != std::string::npos) {
      const std::string block = buffer.substr(0, end);
      buffer.erase(0, end + 2);
      SseEvent e;
      std::istringstream lines(block);
      std::string line;
      while (std::getline(lines, line)) {
        if (line.rfind("id: ", 0) == 0) e.id = std::stoull(line.substr(4));
        if (line.rfind("event: ", 0) == 0) e.type = line.substr(7);
        if (line.rfind("data: ", 0) == 0) e.data = line.substr(6);
      }
      if (!e.type.empty()) events.push_back(e);
    }
    return !(stop && stop(events));
  });
  return events;
}

TEST_F(ServiceTest, JobEventsEndWithTheTerminalStateAndReplayFromLastEventId) {
  start();
  const std::string id = submit(*client_, cornell_job(48, 64));
  const auto events = read_events(daemon_->port(), "/v1/jobs/" + id + "/events");
  ASSERT_GE(events.size(), 3u);
  EXPECT_EQ(events.front().type, "state");
  EXPECT_EQ(events.back().type, "state");
  EXPECT_EQ(json::parse(events.back().data)["state"], "succeeded");
  std::set<std::string> types;
  for (size_t i = 0; i < events.size(); ++i) {
    types.insert(events[i].type);
    if (i > 0) {
      EXPECT_GT(events[i].id, events[i - 1].id);
    }
    EXPECT_FALSE(json::parse(events[i].data, nullptr, false).is_discarded());
  }
  EXPECT_TRUE(types.count("progress"));
  EXPECT_TRUE(types.count("preview"));
  // A reconnect after event n gets exactly the buffered events after n.
  const uint64_t n = events[events.size() / 2].id;
  const auto replay =
      read_events(daemon_->port(), "/v1/jobs/" + id + "/events", {{"Last-Event-ID", std::to_string(n)}});
  ASSERT_FALSE(replay.empty());
  EXPECT_EQ(replay.front().id, n + 1);
  EXPECT_EQ(replay.back().id, events.back().id);
  // The global stream replays too, and its events carry job ids.
  const auto all = read_events(daemon_->port(), "/v1/events", {{"Last-Event-ID", "0"}},
                               [&](const std::vector<SseEvent>& e) { return e.size() >= 3; });
  ASSERT_GE(all.size(), 3u);
  EXPECT_EQ(json::parse(all[0].data)["id"], id);
}

// ---- scheduling ----------------------------------------------------------------------------------------------

TEST_F(ServiceTest, PrioritiesPauseResumeRequeue) {
  start(args({"--max-jobs", "1"}));
  const std::string a = submit(*client_, long_cornell_job());
  // Wait for a finished pass, not just "running": a pause that arrives while the scene still loads stops the job
  // before its first pass, with nothing to checkpoint (samples_done 0), which is right but not what is tested here.
  wait_for(*client_, a, [](const json& s) { return s["progress"]["passes"].get<int>() >= 1; });
  const std::string b = submit(*client_, long_cornell_job()), c = submit(*client_, long_cornell_job());
  EXPECT_EQ(get_job(*client_, b)["queue_position"], 1);
  EXPECT_EQ(get_job(*client_, c)["queue_position"], 2);
  EXPECT_TRUE(get_job(*client_, a)["queue_position"].is_null());
  // PATCH priority: c jumps ahead.
  auto res = client_->Patch("/v1/jobs/" + c, R"({"priority": 7})", "application/json");
  expect_status(res, 200, "patch");
  EXPECT_EQ(get_job(*client_, c)["queue_position"], 1);
  expect_status(client_->Patch("/v1/jobs/" + c, R"({"priority": 700})", "application/json"), 422, "patch range");
  expect_status(client_->Patch("/v1/jobs/" + c, R"({"state": "done"})", "application/json"), 422, "patch key");
  // Pause the running job: it ends its pass, keeps its checkpoint; c (priority 7) runs next.
  res = client_->Post("/v1/jobs/" + a + "/pause");
  ASSERT_TRUE(res);
  EXPECT_TRUE(res->status == 200 || res->status == 202) << res->body;
  const json paused = wait_for(*client_, a, in_state("paused"));
  EXPECT_GT(paused["progress"]["samples_done"].get<int>(), 0);
  EXPECT_TRUE(fs::exists(data_ / "jobs" / a / "checkpoint.bin"));
  wait_for(*client_, c, in_state("running"));
  expect_status(client_->Post("/v1/jobs/" + b + "/resume"), 409, "resume a queued job");
  expect_status(client_->Post("/v1/jobs/" + a + "/resume"), 200, "resume");
  EXPECT_EQ(get_job(*client_, a)["state"], "queued");
  // Cancel, then requeue from scratch.
  expect_status(client_->Post("/v1/jobs/" + b + "/cancel"), 200, "cancel queued");
  expect_status(client_->Post("/v1/jobs/" + b + "/pause"), 409, "pause cancelled");
  expect_status(client_->Post("/v1/jobs/" + b + "/requeue"), 200, "requeue");
  EXPECT_EQ(get_job(*client_, b)["state"], "queued");
  expect_status(client_->Post("/v1/jobs/" + b + "/requeue"), 409, "requeue queued");
  for (const std::string& id : {a, b, c}) client_->Post("/v1/jobs/" + id + "/cancel");
}

TEST_F(ServiceTest, IdempotencyETagsPaginationRetryAfter) {
  start();
  const std::string body = cornell_job(16, 2).dump();
  httplib::Headers key = {{"Idempotency-Key", "order-42"}};
  auto first = client_->Post("/v1/jobs", key, body, "application/json");
  expect_status(first, 202, "first");
  EXPECT_FALSE(first->get_header_value("Retry-After").empty());
  auto again = client_->Post("/v1/jobs", key, body, "application/json");
  expect_status(again, 200, "retry");
  const std::string id = json::parse(first->body)["id"];
  EXPECT_EQ(json::parse(again->body)["id"], id);
  expect_status(client_->Post("/v1/jobs", key, cornell_job(16, 3).dump(), "application/json"), 422, "other body");
  expect_status(client_->Post("/v1/jobs", {{"Idempotency-Key", std::string(300, 'k')}}, body, "application/json"), 400,
                "long key");
  wait_for(*client_, id, in_state("succeeded"));
  // ETag and 304.
  auto png = client_->Get("/v1/jobs/" + id + "/result.png");
  expect_status(png, 200, "png");
  const std::string etag = png->get_header_value("ETag");
  ASSERT_FALSE(etag.empty());
  auto not_modified = client_->Get("/v1/jobs/" + id + "/result.png", {{"If-None-Match", etag}});
  expect_status(not_modified, 304, "304");
  EXPECT_TRUE(not_modified->body.empty());
  EXPECT_EQ(client_->Get("/v1/jobs/" + id + "/result.png", {{"If-None-Match", "\"other\""}})->status, 200);
  // Cursor pagination over 7 jobs, 3 a page: every job once, newest first.
  std::vector<std::string> ids = {id};
  for (int i = 0; i < 6; ++i) ids.push_back(submit(*client_, cornell_job(8, 1)));
  std::vector<std::string> seen;
  std::string cursor;
  for (int page = 0; page < 10; ++page) {
    auto res = client_->Get("/v1/jobs?limit=3" + (cursor.empty() ? "" : "&cursor=" + cursor));
    expect_status(res, 200, "page");
    const json list = json::parse(res->body);
    for (const json& j : list["jobs"]) seen.push_back(j["id"]);
    if (list["next_cursor"].is_null()) break;
    cursor = list["next_cursor"];
  }
  std::reverse(ids.begin(), ids.end());
  EXPECT_EQ(seen, ids);
  expect_status(client_->Get("/v1/jobs?cursor=zzz"), 400, "bad cursor");
  auto filtered = json::parse(client_->Get("/v1/jobs?state=queued,running,succeeded&limit=50")->body);
  EXPECT_EQ(filtered["jobs"].size(), 7u);
}

// ---- who may do what -----------------------------------------------------------------------------------------

TEST_F(ServiceTest, TokensIsolateUsersAdminsSeeAllCorsOnlyForConfiguredOrigins) {
  const std::string alice = "alice-token-0123456789", bob = "bob-token-0123456789", root = "root-token-0123456789";
  const fs::path tokens = dir_.path() / "tokens.json";
  std::ofstream(tokens) << json::array({{{"token", alice}, {"name", "alice"}, {"role", "user"}},
                                        {{"token", bob}, {"name", "bob"}, {"role", "user"}},
                                        {{"token", root}, {"name", "ops"}, {"role", "admin"}}});
  start(args({"--tokens", tokens.string(), "--max-user-priority", "10", "--cors-origin", "https://app.example",
              "--max-queued-per-user", "3", "--max-jobs", "1"}));
  expect_status(client_->Get("/v1/jobs"), 401, "no token");
  expect_status(client_->Get("/v1/jobs", bearer("wrong-token-0123456789")), 401, "bad token");
  expect_status(client_->Get("/v1/jobs", {{"Authorization", "Basic YWxpY2U6eA=="}}), 401, "basic auth");
  EXPECT_EQ(client_->Get("/livez")->status, 200);
  EXPECT_EQ(client_->Get("/metrics")->status, 200);
  EXPECT_EQ(client_->Get("/")->status, 200);

  const std::string a = submit(*client_, long_cornell_job(), bearer(alice));
  EXPECT_EQ(get_job(*client_, a, bearer(alice))["owner"], "alice");
  expect_status(client_->Get("/v1/jobs/" + a, bearer(bob)), 404, "bob reads alice's job");
  expect_status(client_->Get("/v1/jobs/" + a + "/log", bearer(bob)), 404, "bob reads alice's log");
  expect_status(client_->Get("/v1/jobs/" + a + "/document", bearer(bob)), 404, "bob reads alice's document");
  auto document = client_->Get("/v1/jobs/" + a + "/document", bearer(alice));
  ASSERT_TRUE(document);
  EXPECT_EQ(document->status, 200);
  EXPECT_EQ(document->get_header_value("Content-Type"), "application/json");
  EXPECT_EQ(json::parse(document->body), long_cornell_job());  // as submitted
  EXPECT_EQ(client_->Get("/v1/jobs/" + a + "/log", bearer(alice))->status, 200);
  expect_status(client_->Post("/v1/jobs/" + a + "/cancel", bearer(bob)), 404, "bob cancels alice's job");
  expect_status(client_->Delete("/v1/jobs/" + a, bearer(bob)), 404, "bob deletes alice's job");
  EXPECT_TRUE(json::parse(client_->Get("/v1/jobs", bearer(bob))->body)["jobs"].empty());
  EXPECT_EQ(json::parse(client_->Get("/v1/jobs", bearer(root))->body)["jobs"].size(), 1u);
  EXPECT_EQ(client_->Get("/v1/jobs/" + a, bearer(root))->status, 200);
  // Priority above the cap: admin only.
  json urgent = cornell_job(8, 1);
  urgent["priority"] = 50;
  expect_status(client_->Post("/v1/jobs", bearer(alice), urgent.dump(), "application/json"), 403, "user priority");
  expect_status(client_->Patch("/v1/jobs/" + a, bearer(alice), R"({"priority": 50})", "application/json"), 403,
                "user patch priority");
  EXPECT_EQ(client_->Post("/v1/jobs", bearer(root), urgent.dump(), "application/json")->status, 202);
  // Queue limit per user: 429 with Retry-After (alice's first job runs, the next three wait).
  wait_for(*client_, a, in_state("running"), 60, bearer(alice));
  for (int i = 0; i < 3; ++i) submit(*client_, long_cornell_job(), bearer(alice));
  auto limited = client_->Post("/v1/jobs", bearer(alice), long_cornell_job().dump(), "application/json");
  expect_status(limited, 429, "queue limit");
  EXPECT_FALSE(limited->get_header_value("Retry-After").empty());
  EXPECT_EQ(client_->Post("/v1/jobs", bearer(bob), cornell_job(8, 1).dump(), "application/json")->status, 202);
  // Event streams take ?access_token= and show only the caller's jobs.
  const auto events = read_events(daemon_->port(), "/v1/events?access_token=" + bob, {{"Last-Event-ID", "0"}},
                                  [](const std::vector<SseEvent>& e) { return !e.empty(); });
  ASSERT_FALSE(events.empty());
  for (const SseEvent& e : events) EXPECT_EQ(e.data.find(a), std::string::npos);
  expect_status(client_->Get("/v1/events?access_token=nope"), 401, "sse bad token");
  // CORS: the configured origin only.
  auto pre =
      client_->Options("/v1/jobs", {{"Origin", "https://app.example"}, {"Access-Control-Request-Method", "POST"}});
  ASSERT_TRUE(pre);
  EXPECT_EQ(pre->status, 204);
  EXPECT_EQ(pre->get_header_value("Access-Control-Allow-Origin"), "https://app.example");
  EXPECT_NE(pre->get_header_value("Access-Control-Allow-Headers").find("Authorization"), std::string::npos);
  auto evil = client_->Options("/v1/jobs", {{"Origin", "https://evil.example"}});
  ASSERT_TRUE(evil);
  EXPECT_EQ(evil->status, 403);
  EXPECT_TRUE(evil->get_header_value("Access-Control-Allow-Origin").empty());
  auto get = client_->Get("/v1/jobs", {{"Origin", "https://evil.example"}, {"Authorization", "Bearer " + root}});
  EXPECT_TRUE(get->get_header_value("Access-Control-Allow-Origin").empty());
  // SIGHUP re-reads the tokens: bob's goes away.
  std::ofstream(tokens) << json::array({{{"token", root}, {"name", "ops"}, {"role", "admin"}}});
  kill(daemon_->pid(), SIGHUP);
  for (int i = 0; i < 100 && client_->Get("/v1/jobs", bearer(bob))->status != 401; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_EQ(client_->Get("/v1/jobs", bearer(bob))->status, 401);
  // Tokens never reach the log.
  const std::string log = daemon_->log();
  for (const std::string& t : {alice, bob, root}) EXPECT_EQ(log.find(t), std::string::npos) << t;
}

// ---- operations ----------------------------------------------------------------------------------------------

TEST_F(ServiceTest, MetricsPassPromtool) {
  start();
  wait_for(*client_, submit(*client_, cornell_job(16, 4)), in_state("succeeded"));
  client_->Get("/v1/jobs/0123456789abcdef0123456789abcdef");
  const std::string text = client_->Get("/metrics")->body;
  for (const char* name :
       {"tessera_jobs{state=\"succeeded\"} 1", "tessera_queue_length ", "tessera_samples_rendered_total ",
        "tessera_job_duration_seconds_count 1", "tessera_http_requests_total{route=\"/v1/jobs/{id}\",code=\"404\"} 1",
        "tessera_render_threads_busy "})
    EXPECT_NE(text.find(name), std::string::npos) << name << "\n" << text;
  EXPECT_EQ(text.find("0123456789abcdef"), std::string::npos);  // no ids as labels
  const fs::path file = dir_.path() / "metrics.txt";
  std::ofstream(file) << text;
  const int rc =
      std::system(("promtool check metrics < " + file.string() + " > " + file.string() + ".out 2>&1").c_str());
  ASSERT_NE(rc, -1);
  EXPECT_EQ(WEXITSTATUS(rc), 0) << "promtool (Debian package prometheus) says:\n" << read_text(file.string() + ".out");
}

TEST_F(ServiceTest, SigtermDrainsWithACheckpointAndTheJobResumes) {
  start(args({"--grace-s", "10"}));
  const std::string id = submit(*client_, long_cornell_job());
  wait_for(*client_, id, [](const json& s) { return s["progress"]["passes"].get<int>() >= 3; });
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(daemon_->stop(SIGTERM), 0);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(15));  // the grace time, generously
  EXPECT_TRUE(fs::exists(data_ / "jobs" / id / "checkpoint.bin"));
  daemon_ = std::make_unique<Daemon>(data_, args());
  client_ = daemon_->client();
  const json resumed = wait_for(*client_, id, [](const json& s) { return s["progress"]["passes"].get<int>() >= 1; });
  EXPECT_NE(daemon_->log().find("resumed from its checkpoint"), std::string::npos);
  client_->Post("/v1/jobs/" + id + "/cancel");
}

// ---- hostile requests ----------------------------------------------------------------------------------------

TEST_F(ServiceTest, SixtyHostileRequestsGetTheRight4xx) {
  const fs::path tokens = dir_.path() / "tokens.json";
  const std::string user = "user-token-0123456789";
  std::ofstream(tokens) << json::array({{{"token", user}, {"name", "u"}, {"role", "user"}}});
  start(args({"--tokens", tokens.string(), "--max-work", "1e9"}));
  const auto auth = bearer(user);
  struct Case {
    std::string name, method, path, content_type, body;
    int status;
    httplib::Headers headers;
  };
  auto job_with = [](const std::string& patch) { return cornell_job(32, 8).patch(json::parse(patch)).dump(); };
  const std::string J = "application/json";
  std::vector<Case> cases = {
      {"not JSON", "POST", "/v1/jobs", J, "{", 400, {}},
      {"NaN literal", "POST", "/v1/jobs", J, R"({"kind":"scene","render":{"width":NaN}})", 400, {}},
      {"Infinity literal", "POST", "/v1/jobs", J, R"({"kind":"scene","render":{"width":Infinity}})", 400, {}},
      {"trailing garbage", "POST", "/v1/jobs", J, cornell_job(32, 8).dump() + "}", 400, {}},
      {"empty", "POST", "/v1/jobs", J, "", 400, {}},
      {"whitespace", "POST", "/v1/jobs", J, "   \n ", 400, {}},
      {"null", "POST", "/v1/jobs", J, "null", 422, {}},
      {"string", "POST", "/v1/jobs", J, "\"job\"", 422, {}},
      {"number", "POST", "/v1/jobs", J, "42", 422, {}},
      {"deep arrays", "POST", "/v1/jobs", J, std::string(10000, '[') + std::string(10000, ']'), 422, {}},
      {"deep objects",
       "POST",
       "/v1/jobs",
       J,
       [] {
         std::string s;
         for (int i = 0; i < 5000; ++i) s += "{\"a\":";
         s += "1";
         for (int i = 0; i < 5000; ++i) s += "}";
         return s;
       }(),
       422,
       {}},
      {"long string",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/kind","value":")" + std::string(100000, 'x') + "\"}]"),
       422,
       {}},
      {"long material name",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/scene/materials/)" + std::string(1000, 'm') +
                R"(","value":{"type":"lambert"}}])"),
       422,
       {}},
      {"width string",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/render/width","value":"64"}])"),
       422,
       {}},
      {"width float",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/render/width","value":64.5}])"),
       422,
       {}},
      {"width negative",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/render/width","value":-1}])"),
       422,
       {}},
      {"width huge",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/render/width","value":1e308}])"),
       422,
       {}},
      {"height zero",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/render/height","value":0}])"),
       422,
       {}},
      {"spp huge",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/render/spp","value":99999999999}])"),
       422,
       {}},
      {"spp negative",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/render/spp","value":-5}])"),
       422,
       {}},
      {"seed negative",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/render/seed","value":-5}])"),
       422,
       {}},
      {"max_depth huge",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/render/max_depth","value":100000}])"),
       422,
       {}},
      {"time limit negative",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/render/time_limit_s","value":-1}])"),
       422,
       {}},
      {"noise target NaN string",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/render/noise_target","value":"NaN"}])"),
       422,
       {}},
      {"bad sampler",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/render/sampler","value":"halton"}])"),
       422,
       {}},
      {"bad tonemap",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/render/tonemap","value":"reinhard"}])"),
       422,
       {}},
      {"unknown render key",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/render/turbo","value":true}])"),
       422,
       {}},
      {"unknown top key", "POST", "/v1/jobs", J, job_with(R"([{"op":"add","path":"/owner","value":"root"}])"), 422, {}},
      {"priority too high",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/priority","value":1000}])"),
       422,
       {}},
      {"priority float", "POST", "/v1/jobs", J, job_with(R"([{"op":"add","path":"/priority","value":1.5}])"), 422, {}},
      {"outputs bad", "POST", "/v1/jobs", J, job_with(R"([{"op":"add","path":"/outputs","value":["tiff"]}])"), 422, {}},
      {"outputs empty", "POST", "/v1/jobs", J, job_with(R"([{"op":"add","path":"/outputs","value":[]}])"), 422, {}},
      {"coordinate NaN string",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/scene/camera/from/0","value":"NaN"}])"),
       422,
       {}},
      {"coordinate huge",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/scene/camera/from/0","value":1e300}])"),
       422,
       {}},
      {"camera to == from",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"copy","from":"/scene/camera/from","path":"/scene/camera/to"}])"),
       422,
       {}},
      {"fov 180",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/scene/camera/fov_deg","value":180}])"),
       422,
       {}},
      {"gltf camera without gltf",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/scene/camera","value":{"gltf":0}}])"),
       422,
       {}},
      {"gltf path not id",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/scene/gltf","value":"../../etc/passwd"}])"),
       422,
       {}},
      {"unknown gltf id",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/scene/gltf","value":")" + std::string(64, 'f') + "\"}]"),
       422,
       {}},
      {"env map path",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/scene/environment","value":{"map":"/etc/passwd"}}])"),
       422,
       {}},
      {"env rotation 720",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"add","path":"/scene/environment","value":{"rotation_deg":720}}])"),
       422,
       {}},
      {"objects null",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/scene/objects","value":null}])"),
       422,
       {}},
      {"unknown material",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/scene/objects/0/material","value":"nope"}])"),
       422,
       {}},
      {"index out of range",
       "POST",
       "/v1/jobs",
       J,
       job_with(R"([{"op":"replace","path":"/scene/objects/6/indices/0","value":1000000}])"),
       422,
       {}},
      {"radius negative",
       "POST",
       "/v1/jobs",
       J,
       job_with(
           R"([{"op":"add","path":"/scene/objects/-","value":{"shape":"sphere","center":[0,0,0],"radius":-1,"material":"white"}}])"),
       422,
       {}},
      {"work above --max-work",
       "POST",
       "/v1/jobs",
       J,
       job_with(
           R"([{"op":"replace","path":"/render/spp","value":60000},{"op":"replace","path":"/render/width","value":1024},{"op":"replace","path":"/render/height","value":1024}])"),
       422,
       {}},
      {"work in scattering media above --max-work",
       "POST",
       "/v1/jobs",
       J,
       job_with(
           R"([{"op":"replace","path":"/render/spp","value":400},{"op":"replace","path":"/render/width","value":512},{"op":"replace","path":"/render/height","value":512},{"op":"add","path":"/scene/materials/fog_boundary","value":{"type":"interface"}},{"op":"add","path":"/scene/objects/-","value":{"shape":"sphere","center":[0,0,0],"radius":0.2,"material":"fog_boundary","medium":{"sigma_a":[0,0,0],"sigma_s":[1,1,1],"g":0}}}])"),
       422,
       {}},
      {"bdpt's joins in scattering media above --max-work",
       "POST",
       "/v1/jobs",
       J,
       job_with(
           R"([{"op":"replace","path":"/render/spp","value":64},{"op":"replace","path":"/render/width","value":64},{"op":"replace","path":"/render/height","value":64},{"op":"add","path":"/render/integrator","value":"bdpt"},{"op":"add","path":"/scene/materials/fog_boundary","value":{"type":"interface"}},{"op":"add","path":"/scene/objects/-","value":{"shape":"sphere","center":[0,0,0],"radius":0.2,"material":"fog_boundary","medium":{"sigma_a":[0,0,0],"sigma_s":[1,1,1],"g":0}}}])"),
       422,
       {}},
      {"text/plain", "POST", "/v1/jobs", "text/plain", cornell_job(32, 8).dump(), 415, {}},
      {"no content type", "POST", "/v1/jobs", "", cornell_job(32, 8).dump(), 415, {}},
      {"xml", "POST", "/v1/jobs", "application/xml", "<job/>", 415, {}},
      {"multipart without job",
       "POST",
       "/v1/jobs",
       "multipart/form-data; boundary=XyZ",
       "--XyZ\r\nContent-Disposition: form-data; name=\"x\"\r\n\r\n1\r\n--XyZ--\r\n",
       422,
       {}},
      {"oversized", "POST", "/v1/jobs", J, std::string(9 << 20, ' '), 413, {}},
      {"PUT jobs", "PUT", "/v1/jobs", J, "{}", 405, {}},
      {"DELETE jobs", "DELETE", "/v1/jobs", "", "", 405, {}},
      {"POST job", "POST", "/v1/jobs/0123456789abcdef0123456789abcdef", J, "{}", 405, {}},
      {"GET cancel", "GET", "/v1/jobs/0123456789abcdef0123456789abcdef/cancel", "", "", 405, {}},
      {"PATCH metrics", "PATCH", "/metrics", J, "{}", 405, {}},
      {"unknown route", "GET", "/v2/jobs", "", "", 404, {}},
      {"unknown deep route", "GET", "/v1/jobs/a/b/c/d", "", "", 404, {}},
      {"traversal id", "GET", "/v1/jobs/..%2F..%2Fjobs.db", "", "", 404, {}},
      {"traversal result", "GET", "/v1/jobs/../../jobs.db/result.png", "", "", 404, {}},
      {"traversal web file", "GET", "/..%2F..%2Fetc%2Fpasswd.js", "", "", 404, {}},
      {"traversal asset", "GET", "/v1/assets/..%2Fjobs.db", "", "", 404, {}},
      {"unknown job", "GET", "/v1/jobs/0123456789abcdef0123456789abcdef", "", "", 404, {}},
      {"bad state filter", "GET", "/v1/jobs?state=done", "", "", 400, {}},
      {"bad limit", "GET", "/v1/jobs?limit=-1", "", "", 400, {}},
      {"huge limit", "GET", "/v1/jobs?limit=99999999999999999999", "", "", 400, {}},
      {"bad cursor", "GET", "/v1/jobs?cursor=s-1", "", "", 400, {}},
      {"patch not JSON", "PATCH", "/v1/jobs/0123456789abcdef0123456789abcdef", J, "{", 404, {}},
      {"no token", "GET", "/v1/jobs", "", "", 401, {{"Authorization", ""}}},
      {"bad token", "GET", "/v1/jobs", "", "", 401, {{"Authorization", "Bearer nope"}}},
      {"huge token", "GET", "/v1/jobs", "", "", 401, {{"Authorization", "Bearer " + std::string(3000, 'x')}}},
      {"lowercase bearer", "GET", "/v1/jobs", "", "", 401, {{"Authorization", "bearer " + user}}},
      {"token in query on non-SSE", "GET", "/v1/jobs?access_token=" + user, "", "", 401, {{"Authorization", ""}}},
      {"bad idempotency key",
       "POST",
       "/v1/jobs",
       J,
       cornell_job(32, 8).dump(),
       400,
       {{"Idempotency-Key", "has space"}}},
  };
  ASSERT_GE(cases.size(), 60u);
  for (const Case& c : cases) {
    httplib::Headers h = c.headers;
    if (!h.count("Authorization")) h.emplace("Authorization", "Bearer " + user);
    for (auto it = h.begin(); it != h.end();) it = it->second.empty() ? h.erase(it) : std::next(it);
    httplib::Result res = [&] {
      if (c.method == "GET") return client_->Get(c.path, h);
      if (c.method == "DELETE") return client_->Delete(c.path, h);
      if (c.method == "PUT") return client_->Put(c.path, h, c.body, c.content_type);
      if (c.method == "PATCH") return client_->Patch(c.path, h, c.body, c.content_type);
      return client_->Post(c.path, h, c.body, c.content_type);
    }();
    expect_status(res, c.status, c.name);
    if (res && res->status >= 400) {
      const json p = json::parse(res->body, nullptr, false);
      EXPECT_FALSE(proto::contract_schemas().validate(p, "problem.schema.json"))
          << c.name << ": " << res->body.substr(0, 300);
    }
    expect_alive(*client_, c.name);
  }
  EXPECT_TRUE(json::parse(client_->Get("/v1/jobs", auth)->body)["jobs"].empty());
}

// ---- nothing lost --------------------------------------------------------------------------------------------

// Each renders for a few seconds on two threads, over several of the kill loop's rounds (each of which also starts a
// worker process), and passes checkpoints on the way.
json crash_job(int i) {
  json doc = cornell_job(64, 384 + 64 * i);
  doc["render"]["seed"] = 100 + i;
  doc["render"]["exr_precision"] = "float";
  return doc;
}

TEST(ServiceCrash, KillLoopLosesNothingAndResumedRendersAreBitIdentical) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  // A job may be rendering at many of the twelve kills: each counts as a crash of its run (--crash-retries), which
  // this test, about what survives kills, allows without limit.
  const auto a = args({"--log-level", "info", "--crash-retries", "1000"});
  std::vector<std::string> ids;
  std::map<std::string, std::string> finished_png;  // outputs seen so far must never change
  std::mt19937 rng(12345);
  int resumes = 0;
  for (int round = 0; round < 12; ++round) {
    Daemon daemon(data, a);
    auto c = daemon.client();
    if (round < 3)
      for (int i = 0; i < 2; ++i) ids.push_back(submit(*c, crash_job(static_cast<int>(ids.size()))));
    for (const auto& [id, png] : finished_png)
      EXPECT_EQ(c->Get("/v1/jobs/" + id + "/result.png")->body, png) << "round " << round;
    // Long enough, at times, for a render to start in its worker process and pass a checkpoint.
    std::this_thread::sleep_for(std::chrono::milliseconds(std::uniform_int_distribution<int>(300, 2000)(rng)));
    for (const std::string& id : ids) {
      const json s = get_job(*c, id);
      if (s.value("state", "") == "succeeded" && !finished_png.count(id))
        finished_png[id] = c->Get("/v1/jobs/" + id + "/result.png")->body;
    }
    const std::string log = daemon.log();
    for (size_t at = 0; (at = log.find("resumed from its checkpoint", at)) != std::string::npos; ++at) ++resumes;
    EXPECT_EQ(daemon.stop(SIGKILL), 128 + SIGKILL);
  }
  EXPECT_GT(resumes, 0) << "no render was ever resumed: the loop tested nothing";
  // Last start: everything finishes; nothing lost or duplicated.
  Daemon daemon(data, a);
  auto c = daemon.client();
  for (const std::string& id : ids) EXPECT_EQ(wait_for(*c, id, ended, 120).value("state", ""), "succeeded");
  const json list = json::parse(c->Get("/v1/jobs?limit=1000")->body);
  std::multiset<std::string> listed;
  for (const json& j : list["jobs"]) listed.insert(j["id"].get<std::string>());
  EXPECT_EQ(listed, std::multiset<std::string>(ids.begin(), ids.end()));
  for (const auto& [id, png] : finished_png) EXPECT_EQ(c->Get("/v1/jobs/" + id + "/result.png")->body, png);

  // The reference: the same jobs rendered without interruption.
  Daemon reference(dir.path() / "reference", a);
  auto r = reference.client();
  for (size_t i = 0; i < ids.size(); ++i) {
    const std::string ref = submit(*r, crash_job(static_cast<int>(i)));
    wait_for(*r, ref, in_state("succeeded"), 120);
    const fs::path got = dir.path() / ("got" + std::to_string(i) + ".exr"),
                   want = dir.path() / ("want" + std::to_string(i) + ".exr");
    std::ofstream(got, std::ios::binary) << c->Get("/v1/jobs/" + ids[i] + "/result.exr")->body;
    std::ofstream(want, std::ios::binary) << r->Get("/v1/jobs/" + ref + "/result.exr")->body;
    const ImageData g = read_image(got.string()), w = read_image(want.string());
    ASSERT_EQ(g.pixels.size(), w.pixels.size());
    EXPECT_EQ(std::memcmp(g.pixels.data(), w.pixels.data(), g.pixels.size() * sizeof(float)), 0)
        << "job " << i << ": the resumed render differs from the uninterrupted one";
  }
}

// ---- bounded load (loopback) ---------------------------------------------------------------------------------

TEST_F(ServiceTest, AThousandQueuedJobsTwoHundredWatchersAndPolling) {
  // 209 connections from one address: as many clients as behind one proxy.
  start(args({"--max-jobs", "1", "--log-level", "warn", "--max-connections-per-client", "0"}));
  const std::string blocker = submit(*client_, long_cornell_job());
  wait_for(*client_, blocker, in_state("running"));
  // 200 watchers of the global stream.
  std::atomic<int> watching{0}, saw_job{0};
  std::atomic<bool> done{false};
  std::vector<std::thread> watchers;
  for (int i = 0; i < 200; ++i) {
    watchers.emplace_back([&] {
      // Like an EventSource: reconnect (with Last-Event-ID) when the connection fails, e.g. when 200 connects at
      // once overflow the listen backlog.
      bool counted = false, seen = false;
      uint64_t last_id = 0;
      for (int attempt = 0; attempt < 20 && !done.load(); ++attempt) {
        httplib::Client w("127.0.0.1", daemon_->port());
        w.set_connection_timeout(5);
        w.set_read_timeout(120);
        httplib::Headers h;
        if (counted) h.emplace("Last-Event-ID", std::to_string(last_id));
        // The receiver gets the stream as the socket delivers it (at most 4 KiB at a time, possibly less), so a
        // piece can end anywhere, even inside "id: 123": only complete lines are looked at.
        std::string pending;
        w.Get("/v1/events", h, [&](const char* d, size_t n) {
          if (!counted) {
            counted = true;
            ++watching;
          }
          pending.append(d, n);
          size_t start = 0;
          for (size_t end; (end = pending.find('\n', start)) != std::string::npos; start = end + 1) {
            const std::string_view line(pending.data() + start, end - start);
            if (line.starts_with("id: ")) {
              const std::string_view digits = line.substr(4);
              uint64_t id = 0;
              const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), id);
              if (ec != std::errc() || ptr != digits.data() + digits.size()) {
                ADD_FAILURE() << "an event id that is not a number: \"" << line << "\"";
              } else {
                last_id = id;
              }
            }
            if (!seen && line.starts_with("data: ") && line.find("\"state\":\"queued\"") != std::string::npos) {
              seen = true;
              ++saw_job;
            }
          }
          pending.erase(0, start);
          return !done.load();
        });
        if (!done.load()) std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
    });
  }
  for (int i = 0; i < 600 && watching.load() < 200; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(watching.load(), 200);
  // 1,000 jobs at once from 8 connections.
  std::vector<std::thread> submitters;
  std::atomic<int> accepted{0};
  for (int t = 0; t < 8; ++t) {
    submitters.emplace_back([&] {
      auto c = daemon_->client();
      const std::string body = cornell_job(8, 1).dump();
      for (int i = 0; i < 125; ++i) {
        auto res = c->Post("/v1/jobs", body, "application/json");
        if (res && res->status == 202) ++accepted;
      }
    });
  }
  // Polling meanwhile.
  std::atomic<int> polls_ok{0}, polls{0};
  std::thread poller([&] {
    auto c = daemon_->client();
    for (int i = 0; i < 300; ++i) {
      ++polls;
      if (auto res = c->Get("/v1/jobs/" + blocker); res && res->status == 200) ++polls_ok;
    }
  });
  for (auto& t : submitters) t.join();
  poller.join();
  EXPECT_EQ(accepted.load(), 1000);
  EXPECT_EQ(polls_ok.load(), polls.load());
  const json queued = json::parse(client_->Get("/v1/jobs?state=queued&limit=1000")->body);
  EXPECT_EQ(queued["jobs"].size(), 1000u);
  std::set<int> positions;
  for (const json& j : queued["jobs"]) positions.insert(j["queue_position"].get<int>());
  EXPECT_EQ(positions.size(), 1000u);
  EXPECT_EQ(*positions.begin(), 1);
  EXPECT_EQ(*positions.rbegin(), 1000);
  for (int i = 0; i < 200 && saw_job.load() < 200; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(saw_job.load(), 200);
  done = true;
  expect_alive(*client_, "load");
  daemon_->stop(SIGKILL);  // the watchers' connections drop
  for (auto& t : watchers) t.join();
}

}  // namespace
}  // namespace tessera::server::test
