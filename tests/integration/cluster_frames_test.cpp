// A frame range across a cluster: three tesserad share one throw-away PostgreSQL and one data directory, and each
// frame of a 24-frame range is a work unit any of them claims. Every frame is rendered once, bit for bit the frame of
// the range rendered by one daemon alone; a node killed (SIGKILL) in the middle of a frame has that frame taken over
// by another past its lease, and only that frame rendered again.
#include <signal.h>

#include <gtest/gtest.h>

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "tests/integration/daemon.h"
#include "tests/integration/daemon_client.h"
#include "tests/integration/node_cluster.h"
#include "tests/server/postgres_cluster.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr int kFrames = 24;

json status_of(httplib::Client& c, const std::string& id) {
  auto res = c.Get("/v1/jobs/" + id);
  return res && res->status == 200 ? json::parse(res->body) : json::object();
}

std::string get(httplib::Client& c, const std::string& path) {
  auto res = c.Get(path);
  return res && res->status == 200 ? res->body : "";
}

// The spinning cube's frames 1-24 at 96x54, 384 spp, as EXR: a frame takes one to two seconds of one thread here.
json range_job(httplib::Client& c) {
  const std::string bytes = read_text(fs::path(TESSERA_SOURCE_DIR) / "examples/spinning_cube/SpinningCube.glb");
  auto up = c.Post("/v1/assets?name=SpinningCube.glb", bytes, "model/gltf-binary");
  EXPECT_TRUE(up && (up->status == 201 || up->status == 200));
  return {{"kind", "scene"},
          {"scene", {{"gltf", up ? json::parse(up->body).value("id", "") : ""}}},
          {"render", {{"width", 96}, {"height", 54}, {"spp", 384}, {"frames", {{"start", 1}, {"end", kFrames}}}}},
          {"outputs", {"exr"}}};
}

// Each frame's EXR of the range rendered by one daemon alone (SQLite, one thread): what the cluster must give.
const std::vector<std::string>& one_node_frames() {
  static const std::vector<std::string> frames = [] {
    TempDir dir;
    Daemon alone(dir.path() / "alone", {"--threads", "1"});
    auto c = alone.client();
    const std::string id = submit(*c, range_job(*c));
    EXPECT_TRUE(eventually([&] { return status_of(*c, id).value("state", "") == "succeeded"; }, 300)) << alone.log();
    std::vector<std::string> out;
    for (int f = 1; f <= kFrames; ++f)
      out.push_back(get(*c, "/v1/jobs/" + id + "/frames/" + std::to_string(f) + "/result.exr"));
    return out;
  }();
  return frames;
}

using Cluster = NodeCluster;

// How many times each frame started rendering, from the job's log.
std::map<int, int> renders_per_frame(const std::string& log) {
  std::map<int, int> out;
  for (int f = 1; f <= kFrames; ++f) {
    const std::string line = "frame " + std::to_string(f) + ": rendering at";
    for (size_t at = log.find(line); at != std::string::npos; at = log.find(line, at + 1)) ++out[f];
  }
  return out;
}

TEST(ClusterFrames, ARangeSpreadOverThreeNodesRendersEachFrameOnceAndExactly) {
  const std::vector<std::string>& reference = one_node_frames();
  ASSERT_EQ(reference.size(), static_cast<size_t>(kFrames));
  Cluster cluster;
  auto c = cluster.node(0).client();
  const std::string id = submit(*c, range_job(*c));
  ASSERT_TRUE(eventually([&] { return status_of(*c, id).value("state", "") == "succeeded"; }, 300)) << cluster.logs();
  EXPECT_EQ(cluster.sql("SELECT units FROM tessera_jobs WHERE id = '" + id + "'"), std::to_string(kFrames));
  // Every node rendered frames.
  EXPECT_EQ(cluster.sql("SELECT COUNT(DISTINCT node) FROM tessera_units WHERE job_id = '" + id + "' AND idx < " +
                        std::to_string(kFrames)),
            "3");
  const std::map<int, int> renders = renders_per_frame(get(*c, "/v1/jobs/" + id + "/log"));
  for (int f = 1; f <= kFrames; ++f) {
    EXPECT_EQ(renders.count(f) ? renders.at(f) : 0, 1) << "frame " << f;
    auto ci = cluster.node(f % 3).client();
    EXPECT_TRUE(get(*ci, "/v1/jobs/" + id + "/frames/" + std::to_string(f) + "/result.exr") == reference[f - 1])
        << "frame " << f << " differs from the one-node render's";
  }
  const json frames = status_of(*c, id)["frames"];
  EXPECT_EQ(frames["done"], kFrames) << frames;
  EXPECT_EQ(frames["done_ranges"], json::parse("[[1, 24]]")) << frames;
}

// A node other than the one answering is killed while it renders a frame (a pass of it recorded, less than half its
// samples: a frame killed after its files were written is kept by the node that takes it over): past its lease another
// node claims that frame's unit under the next epoch and renders it again; no other frame is rendered twice, and every
// frame is the one-node render's.
TEST(ClusterFrames, AKilledNodesFrameIsRenderedElsewhereAndTheOthersAreUntouched) {
  const std::vector<std::string>& reference = one_node_frames();
  ASSERT_EQ(reference.size(), static_cast<size_t>(kFrames));
  Cluster cluster;
  auto c = cluster.node(0).client();
  const std::string id = submit(*c, range_job(*c));
  std::string held;  // node,idx
  ASSERT_TRUE(eventually(
      [&] {
        held = cluster.sql(
            "SELECT node || ',' || idx FROM tessera_units WHERE job_id = '" + id +
            "' AND node IN ('n2', 'n3') AND state = 'running' AND samples_done > 0 AND samples_done < samples / 2 "
            "LIMIT 1");
        return !held.empty();
      },
      120))
      << cluster.logs();
  const std::string victim = held.substr(0, held.find(','));
  const int idx = std::stoi(held.substr(held.find(',') + 1));
  cluster.node(victim == "n2" ? 1 : 2).stop(SIGKILL);
  ASSERT_TRUE(eventually([&] { return status_of(*c, id).value("state", "") == "succeeded"; }, 300)) << cluster.logs();
  EXPECT_NE(cluster.sql("SELECT node FROM tessera_units WHERE job_id = '" + id + "' AND idx = " + std::to_string(idx)),
            victim);
  const std::string log = get(*c, "/v1/jobs/" + id + "/log");
  const std::map<int, int> renders = renders_per_frame(log);
  for (int f = 1; f <= kFrames; ++f) {
    EXPECT_EQ(renders.count(f) ? renders.at(f) : 0, f == idx + 1 ? 2 : 1) << "frame " << f << "\n" << log;
    EXPECT_TRUE(get(*c, "/v1/jobs/" + id + "/frames/" + std::to_string(f) + "/result.exr") == reference[f - 1])
        << "frame " << f << " differs from the one-node render's";
  }
  EXPECT_NE(log.find("node " + victim + " stopped renewing its lease; taken over by this node"), std::string::npos)
      << log;
}

}  // namespace
}  // namespace tessera::server::test
