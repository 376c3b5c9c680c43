// Frame range jobs on the real tesserad (SQLite): every frame is the still of the asset at its time, bit for bit; its
// files are numbered and served per frame; a daemon killed mid-range resumes without rendering its finished frames
// again; a frame whose render dies every time fails the job naming it, the frames before it kept; the status of a
// range of 10,000 frames stays small. Correctness only: no timing assertions.
#include <signal.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "tests/integration/daemon.h"
#include "tests/integration/daemon_client.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const std::vector<std::string> kArgs = {"--threads", "2", "--max-jobs", "1", "--log-level", "debug"};

std::string upload_cube(httplib::Client& c) {
  const std::string bytes = read_text(fs::path(TESSERA_SOURCE_DIR) / "examples/spinning_cube/SpinningCube.glb");
  auto up = c.Post("/v1/assets?name=SpinningCube.glb", bytes, "model/gltf-binary");
  EXPECT_TRUE(up && (up->status == 201 || up->status == 200)) << (up ? up->body : "no answer");
  return up ? json::parse(up->body).value("id", "") : "";
}

json cube_job(const std::string& asset, int width, int height, int spp, const json& frames) {
  json doc = {{"kind", "scene"},
              {"scene", {{"gltf", asset}}},
              {"render", {{"width", width}, {"height", height}, {"spp", spp}}},
              {"outputs", {"exr", "png"}}};
  if (!frames.is_null()) doc["render"]["frames"] = frames;
  return doc;
}

// Modification times of the job's files whose names start with `prefix`, by name.
std::map<std::string, fs::file_time_type> mtimes(const fs::path& dir, const std::string& prefix) {
  std::map<std::string, fs::file_time_type> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.path().filename().string().starts_with(prefix)) out[e.path().filename().string()] = e.last_write_time();
  return out;
}

// Frames 1, 3, ..., 11 of the spinning cube: each frame's EXR and PNG are those of the still at frame / 24 s, served
// per frame and kept as numbered files; the job's own result.exr points at the frames; frames outside the range, not
// done, or not numbers are 404s.
TEST(FrameRanges, EveryFrameIsTheStillAtItsTimeServedPerFrame) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  Daemon daemon(data, kArgs);
  auto c = daemon.client();
  const std::string asset = upload_cube(*c);
  json range = cube_job(asset, 64, 36, 2, {{"start", 1}, {"end", 11}, {"step", 2}});
  range["render"]["aovs"] = {"albedo"};
  const std::string id = submit(*c, range);
  ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "succeeded"; }, 240)) << daemon.log();
  const json done = get_job(*c, id);
  const json& frames = done["frames"];
  EXPECT_EQ(frames.value("total", 0), 6) << done.dump();
  EXPECT_EQ(frames.value("done", 0), 6) << done.dump();
  EXPECT_EQ(frames["done_ranges"], json::parse("[[1, 11]]")) << done.dump();
  EXPECT_EQ(frames["last_done"], 11) << done.dump();
  EXPECT_EQ(done["progress"].value("samples_total", 0), 12) << done.dump();
  const std::string log = fetch(*c, "/v1/jobs/" + id + "/log");
  for (int f = 1; f <= 11; f += 2) {
    json still = cube_job(asset, 64, 36, 2, nullptr);
    still["render"]["aovs"] = {"albedo"};
    still["scene"]["time"] = f / 24.0;
    const std::string still_id = submit(*c, still);
    ASSERT_TRUE(eventually([&] { return state_of(*c, still_id) == "succeeded"; }, 120)) << daemon.log();
    const std::string frame = "/v1/jobs/" + id + "/frames/" + std::to_string(f);
    const std::string exr = fetch(*c, frame + "/result.exr");
    EXPECT_FALSE(exr.empty());
    EXPECT_TRUE(exr == fetch(*c, "/v1/jobs/" + still_id + "/result.exr")) << "frame " << f << " is not its still";
    EXPECT_TRUE(fetch(*c, frame + "/result.png") == fetch(*c, "/v1/jobs/" + still_id + "/result.png"));
    EXPECT_TRUE(fetch(*c, frame + "/aovs/albedo.png") == fetch(*c, "/v1/jobs/" + still_id + "/aovs/albedo.png"));
    char name[32];
    std::snprintf(name, sizeof name, "result.%04d.exr", f);
    EXPECT_TRUE(read_text(data / "jobs" / id / name) == exr) << name;
    EXPECT_NE(log.find("frame " + std::to_string(f) + ": done"), std::string::npos) << log;
  }
  for (const std::string f : {"2", "13", "-1", "x", "1.0"}) {
    auto res = c->Get("/v1/jobs/" + id + "/frames/" + f + "/result.exr");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 404) << f << ": " << res->body;
    EXPECT_EQ(res->get_header_value("Content-Type"), "application/problem+json");
    EXPECT_NE(res->body.find("not one of the job's frames 1-11 step 2"), std::string::npos) << res->body;
  }
  auto no_pass = c->Get("/v1/jobs/" + id + "/frames/1/aovs/normal.png");
  ASSERT_TRUE(no_pass);
  EXPECT_EQ(no_pass->status, 404) << no_pass->body;
  auto whole_pass = c->Get("/v1/jobs/" + id + "/aovs/albedo.png");
  ASSERT_TRUE(whole_pass);
  EXPECT_EQ(whole_pass->status, 409) << whole_pass->body;
  auto whole = c->Get("/v1/jobs/" + id + "/result.exr");
  ASSERT_TRUE(whole);
  EXPECT_EQ(whole->status, 409) << whole->body;
  EXPECT_NE(whole->body.find("/frames/{frame}/result.exr"), std::string::npos) << whole->body;
  // The preview is the last frame's.
  EXPECT_TRUE(fetch(*c, "/v1/jobs/" + id + "/preview.png") == fetch(*c, "/v1/jobs/" + id + "/frames/11/result.png"));
}

// A daemon killed (SIGKILL) while it renders a range resumes it at its next start: the frames it had finished (their
// units done in the store) are neither rendered nor written again: their files keep their times, and the log renders
// each once.
TEST(FrameRanges, ADaemonKilledMidRangeResumesWithoutRenderingItsFinishedFramesAgain) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  std::string id;
  std::map<std::string, fs::file_time_type> before;
  {
    Daemon daemon(data, kArgs);
    auto c = daemon.client();
    const std::string asset = upload_cube(*c);
    id = submit(*c, cube_job(asset, 160, 90, 16, {{"start", 1}, {"end", 24}}));
    ASSERT_TRUE(eventually([&] { return get_job(*c, id)["frames"].value("done", 0) >= 3; }, 240)) << daemon.log();
    daemon.stop(SIGKILL);
    before = mtimes(data / "jobs" / id, "result.");
  }
  // A frame is done once its EXR is written (its PNG comes first): the frame under way may have left its PNG alone.
  std::erase_if(before, [&](const auto& file) {
    const std::string exr = fs::path(file.first).replace_extension(".exr").string();
    return !before.contains(exr);
  });
  const size_t kept_frames = before.size() / 2;
  ASSERT_GE(before.size(), 6u) << "no frames were finished before the kill";
  ASSERT_LT(before.size(), 48u) << "the range was done before the kill";
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // a file written again would have a later time
  Daemon daemon(data, kArgs);
  auto c = daemon.client();
  ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "succeeded"; }, 480)) << daemon.log();
  const auto after = mtimes(data / "jobs" / id, "result.");
  EXPECT_EQ(after.size(), 48u);
  for (const auto& [name, time] : before) {
    ASSERT_TRUE(after.contains(name)) << name;
    EXPECT_EQ(after.at(name), time) << name << " was written again";
  }
  // Each frame finished before the kill was rendered once: its log lines say so.
  const std::string log = fetch(*c, "/v1/jobs/" + id + "/log");
  for (const auto& [name, time] : before) {
    const std::string frame = "frame " + std::to_string(std::stoi(name.substr(7, 4))) + ": rendering at";
    EXPECT_EQ(log.find(frame), log.rfind(frame)) << frame << " twice:\n" << log;
  }
  EXPECT_EQ(kept_frames * 2, before.size());
}

// A frame whose render dies every time (its worker killed while it renders that frame) is rendered again up to
// --crash-retries times, each from that frame, and then fails the job with an error that names the frame; the
// frames before it are kept and served.
TEST(FrameRanges, AFrameThatDiesEveryTimeFailsTheJobNamingItAndKeepsTheFramesBefore) {
  TempDir dir;
  const fs::path data = dir.path() / "data";
  Daemon daemon(data, kArgs);
  auto c = daemon.client();
  const std::string asset = upload_cube(*c);
  const std::string id = submit(*c, cube_job(asset, 320, 180, 128, {{"start", 1}, {"end", 12}}));
  // Two frames done and the next one rendering (between a unit's end and the next claim none is).
  int64_t doomed = -1;
  ASSERT_TRUE(eventually(
      [&] {
        const json frames = get_job(*c, id)["frames"];
        if (frames.value("done", 0) < 2 || frames["running_ranges"].empty()) return false;
        doomed = frames["running_ranges"][0][0].get<int64_t>();
        return true;
      },
      240))
      << daemon.log();
  const auto kept = mtimes(data / "jobs" / id, "result.");
  const std::string started = "frame " + std::to_string(doomed) + ": rendering at";
  auto occurrences = [](const std::string& text, const std::string& what) {
    size_t n = 0;
    for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
  };
  for (size_t run = 1; run <= 3; ++run) {  // the first run and --crash-retries (2) retries
    // Its worker, once it renders the doomed frame (its log says so for this run).
    pid_t worker = 0;
    ASSERT_TRUE(eventually(
        [&] {
          const auto children = children_of(daemon.pid());
          if (state_of(*c, id) != "running" || children.size() != 1) return false;
          if (occurrences(fetch(*c, "/v1/jobs/" + id + "/log"), started) < run) return false;
          worker = children.front();
          return true;
        },
        120))
        << fetch(*c, "/v1/jobs/" + id + "/log");
    ASSERT_EQ(kill(worker, SIGKILL), 0);
    // Gone (the daemon may have started the next run's worker already).
    ASSERT_TRUE(eventually(
        [&] {
          const auto children = children_of(daemon.pid());
          return std::find(children.begin(), children.end(), worker) == children.end();
        },
        60));
  }
  ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "failed"; }, 120)) << daemon.log();
  const json failed = get_job(*c, id);
  EXPECT_NE(failed.value("error", "").find("frame " + std::to_string(doomed) + ": "), std::string::npos)
      << failed.dump();
  EXPECT_EQ(failed["frames"]["failed_ranges"], json::array({json::array({doomed, doomed})})) << failed.dump();
  EXPECT_EQ(mtimes(data / "jobs" / id, "result."), kept) << "frames done before the failure were rendered again";
  EXPECT_EQ(fetch(*c, "/v1/jobs/" + id + "/frames/1/result.exr").empty(), false);
  auto not_done = c->Get("/v1/jobs/" + id + "/frames/" + std::to_string(doomed) + "/result.exr");
  ASSERT_TRUE(not_done);
  EXPECT_EQ(not_done->status, 404);
  EXPECT_NE(not_done->body.find("is not done"), std::string::npos) << not_done->body;
}

// A range of 10,000 frames (the default --max-frames) has a status of a few hundred bytes: counts and ranges, never
// a list of frames.
TEST(FrameRanges, TheStatusOfTenThousandFramesStaysSmall) {
  TempDir dir;
  Daemon daemon(dir.path() / "data", kArgs);
  auto c = daemon.client();
  const std::string asset = upload_cube(*c);
  const std::string id = submit(*c, cube_job(asset, 16, 16, 1, {{"start", 1}, {"end", 10000}}));
  ASSERT_TRUE(eventually([&] { return get_job(*c, id)["frames"].value("done", 0) >= 2; }, 240)) << daemon.log();
  const json s = get_job(*c, id);
  EXPECT_LT(s.dump().size(), 4096u) << s.dump();
  EXPECT_EQ(s["frames"].value("total", 0), 10000);
  auto too_many =
      c->Post("/v1/jobs", cube_job(asset, 16, 16, 1, {{"start", 1}, {"end", 10001}}).dump(), "application/json");
  ASSERT_TRUE(too_many);
  EXPECT_EQ(too_many->status, 422);
  EXPECT_EQ(json::parse(too_many->body).value("pointer", ""), "/render/frames") << too_many->body;
  EXPECT_EQ(c->Post("/v1/jobs/" + id + "/cancel", "", "application/json")->status, 200);
}

}  // namespace
}  // namespace tessera::server::test
