// One frame, many nodes: three tesserad on loopback ports share one throw-away PostgreSQL and one data directory, a
// job's samples are split into work units (--unit-pixel-samples) that the nodes render at once, and the merge of the
// units' films is the EXR one node renders alone, byte for byte: with all nodes up, with one killed (SIGKILL) in the
// middle of a unit (re-leased, resumed from its checkpoint elsewhere), and with one frozen (SIGSTOP) past its lease
// and continued (its late writes refused, as the epoch of its unit run is stale).
#include <signal.h>

#include <gtest/gtest.h>

#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "tests/integration/daemon.h"
#include "tests/integration/node_cluster.h"
#include "tests/server/postgres_cluster.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {
namespace {

using nlohmann::json;

// 64x64 pixels, 9 units of 128 samples: a unit takes one to a few seconds of one thread here.
constexpr int kSize = 64;
constexpr int kSpp = 1152;
constexpr int kUnits = 9;
const std::string kUnitPixelSamples = std::to_string(kSize * kSize * kSpp / kUnits);

std::string submit(httplib::Client& c, const json& doc) {
  auto res = c.Post("/v1/jobs", doc.dump(), "application/json");
  if (!res || res->status != 202) {
    ADD_FAILURE() << "submission refused: " << (res ? res->body : "no answer");
    return "";
  }
  return json::parse(res->body).value("id", "");
}

std::string state_of(httplib::Client& c, const std::string& id) {
  auto res = c.Get("/v1/jobs/" + id);
  return res && res->status == 200 ? json::parse(res->body).value("state", "") : "";
}

std::string exr_of(httplib::Client& c, const std::string& id) {
  auto res = c.Get("/v1/jobs/" + id + "/result.exr");
  return res && res->status == 200 ? res->body : "";
}

json job() {
  json doc = cornell_job(kSize, kSpp);
  doc["outputs"] = {"exr"};
  doc["render"]["exr_precision"] = "float";
  return doc;
}

// The EXR of the job rendered whole by one daemon alone (SQLite, one thread): what every cluster render must equal.
const std::string& one_node_exr() {
  static const std::string exr = [] {
    TempDir dir;
    Daemon alone(dir.path() / "alone", {"--threads", "1"});
    auto c = alone.client();
    const std::string id = submit(*c, job());
    EXPECT_TRUE(eventually([&] { return state_of(*c, id) == "succeeded"; }, 180)) << alone.log();
    return exr_of(*c, id);
  }();
  return exr;
}

struct Cluster : NodeCluster {
  Cluster() : NodeCluster({"--unit-pixel-samples", kUnitPixelSamples}) {}
};

TEST(ClusterUnits, AJobSplitAcrossThreeNodesIsByteIdenticalToTheOneNodeRender) {
  const std::string& reference = one_node_exr();
  ASSERT_FALSE(reference.empty());
  Cluster cluster;
  auto c = cluster.node(0).client();
  const std::string id = submit(*c, job());
  // The preview refines as units finish: there is one (the merge of the units done) while the job still renders.
  EXPECT_TRUE(eventually(
      [&] {
        auto preview = c->Get("/v1/jobs/" + id + "/preview.png");
        return preview && preview->status == 200 && state_of(*c, id) == "running";
      },
      60));
  // While it renders, its status names the units running and the nodes rendering them.
  json running_units;
  EXPECT_TRUE(eventually(
      [&] {
        auto res = c->Get("/v1/jobs/" + id);
        if (!res || res->status != 200) return false;
        running_units = json::parse(res->body)["units"];
        return running_units.is_object() && !running_units["running"].empty();
      },
      60));
  if (running_units.is_object()) {
    EXPECT_EQ(running_units["total"], kUnits);
    for (const json& u : running_units["running"]) {
      EXPECT_TRUE(u["node"] == "n1" || u["node"] == "n2" || u["node"] == "n3") << u;
      EXPECT_GE(u["unit"].get<int>(), 1);
      EXPECT_EQ(u["samples"], kSpp / kUnits);
    }
  }
  ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "succeeded"; }, 180)) << cluster.logs();
  EXPECT_EQ(cluster.sql("SELECT units FROM tessera_jobs WHERE id = '" + id + "'"), std::to_string(kUnits));
  // Done: every unit by the node that rendered it; the wall time against the render time of three nodes at once.
  const json status = json::parse(c->Get("/v1/jobs/" + id)->body);
  const json& units = status["units"];
  EXPECT_EQ(units["done"], kUnits) << units;
  EXPECT_EQ(units["queued"], 0);
  EXPECT_TRUE(units["running"].empty());
  int by_nodes = 0;
  for (const auto& [node, n] : units["done_by_node"].items()) by_nodes += n.get<int>();
  EXPECT_EQ(by_nodes, kUnits) << units;
  EXPECT_EQ(units["done_by_node"].size(), 3u) << units;
  const json& progress = status["progress"];
  EXPECT_GT(progress["render_s"].get<double>(), progress["elapsed_s"].get<double>()) << progress;
  EXPECT_GT(progress["samples_per_s"].get<double>(), 0) << progress;
  // Every node rendered some of its units.
  EXPECT_EQ(cluster.sql("SELECT COUNT(DISTINCT node) FROM tessera_units WHERE job_id = '" + id + "' AND idx < " +
                        std::to_string(kUnits)),
            "3");
  // Any node serves it, and it is the one-node render's file, byte for byte.
  for (int i = 0; i < 3; ++i) {
    auto ci = cluster.node(i).client();
    EXPECT_TRUE(exr_of(*ci, id) == reference) << "node " << i + 1 << "'s EXR differs from the one-node render";
  }
}

// A node other than the one answering (n2 or n3) is killed once a unit it renders has a checkpoint: past its lease
// another node claims the unit under the next epoch and resumes it from that checkpoint; the image is still the
// one-node render's.
TEST(ClusterUnits, AKilledNodesUnitResumesElsewhereAndTheImageIsStillExact) {
  const std::string& reference = one_node_exr();
  ASSERT_FALSE(reference.empty());
  Cluster cluster;
  auto c = cluster.node(0).client();
  const std::string id = submit(*c, job());
  std::string held;  // node,idx,epoch
  ASSERT_TRUE(eventually(
      [&] {
        held = cluster.sql("SELECT node || ',' || idx || ',' || epoch FROM tessera_units WHERE job_id = '" + id +
                           "' AND node IN ('n2', 'n3') AND state = 'running' AND checkpoint_epoch = epoch LIMIT 1");
        return !held.empty();
      },
      120))
      << cluster.logs();
  const std::string victim = held.substr(0, held.find(','));
  const std::string idx = held.substr(victim.size() + 1, held.rfind(',') - victim.size() - 1);
  cluster.node(victim == "n2" ? 1 : 2).stop(SIGKILL);
  ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "succeeded"; }, 180)) << cluster.logs();
  // The unit was taken over (a later epoch, another node) and resumed from the dead node's checkpoint.
  EXPECT_NE(cluster.sql("SELECT node || ',' || idx || ',' || epoch FROM tessera_units WHERE job_id = '" + id +
                        "' AND idx = " + idx),
            held);
  EXPECT_NE(cluster.sql("SELECT node FROM tessera_units WHERE job_id = '" + id + "' AND idx = " + idx), victim);
  EXPECT_NE(cluster.logs().find("job resumed from its checkpoint"), std::string::npos) << cluster.logs();
  EXPECT_TRUE(exr_of(*c, id) == reference) << "the EXR differs from the one-node render";
  // The job's log names the node of every line, and the takeover: which unit, from which node.
  auto log = c->Get(("/v1/jobs/" + id + "/log").c_str());
  ASSERT_TRUE(log && log->status == 200);
  const std::string takeover = "unit " + std::to_string(std::stoi(idx) + 1) + ": node " + victim +
                               " stopped renewing its lease; taken over by this node, resuming from its checkpoint at ";
  EXPECT_NE(log->body.find(takeover), std::string::npos) << log->body;
  for (const std::string& node : {std::string("n1"), std::string(victim == "n2" ? "n3" : "n2")})
    EXPECT_NE(log->body.find("Z  " + node + "  unit "), std::string::npos) << node << "\n" << log->body;
}

// A node (n2 or n3) frozen (SIGSTOP) in the middle of a unit for longer than its lease: the unit is re-leased to
// another node under the next epoch. Continued (SIGCONT) while the job still renders, the frozen node's writes for its
// stale epoch are refused (it stops and records nothing), and the image is still the one-node render's.
TEST(ClusterUnits, ANodeFrozenPastItsLeaseHasItsLateWritesRefused) {
  const std::string& reference = one_node_exr();
  ASSERT_FALSE(reference.empty());
  Cluster cluster;
  auto c = cluster.node(0).client();
  const std::string id = submit(*c, job());
  std::string owner;  // n2 or n3: a node other than the one answering
  std::string held;   // idx,epoch
  Daemon* frozen = nullptr;
  // A unit can end (its end committed) between the query and the SIGSTOP: then it is never taken over, and the node is
  // continued and frozen again in a later unit. A node stopped inside the transaction that ends the unit is not one of
  // these: its transaction is rolled back past its lease, and the unit taken over.
  for (int attempt = 0; attempt < 5 && !frozen; ++attempt) {
    ASSERT_TRUE(eventually(
        [&] {
          const std::string row =
              cluster.sql("SELECT node || ',' || idx || ',' || epoch FROM tessera_units WHERE job_id = '" + id +
                          "' AND node IN ('n2', 'n3') AND state = 'running' AND checkpoint_epoch = epoch LIMIT 1");
          owner = row.substr(0, row.find(','));
          held = row.empty() ? "" : row.substr(owner.size() + 1);
          return !row.empty();
        },
        120))
        << cluster.logs();
    Daemon& node = cluster.node(owner == "n2" ? 1 : 2);
    kill(node.pid(), SIGSTOP);
    const std::string idx = held.substr(0, held.find(','));
    if (cluster.sql("SELECT state FROM tessera_units WHERE job_id = '" + id + "' AND idx = " + idx) == "done")
      kill(node.pid(), SIGCONT);
    else
      frozen = &node;
  }
  ASSERT_NE(frozen, nullptr) << "every unit frozen had already ended";
  const std::string idx = held.substr(0, held.find(','));
  const std::string stale_epoch = held.substr(held.find(',') + 1);
  const std::string unit = "SELECT idx || ',' || epoch FROM tessera_units WHERE job_id = '" + id + "' AND idx = " + idx;
  // Taken over by another node under a newer epoch.
  ASSERT_TRUE(eventually([&] { return cluster.sql(unit) != held; }, 60)) << cluster.logs();
  kill(frozen->pid(), SIGCONT);
  // Its render stops at its next lease renewal, or, stopped while it recorded the unit's end, that end is refused.
  ASSERT_TRUE(eventually(
      [&] {
        const std::string log = frozen->log();
        return log.find("changed or taken over elsewhere") != std::string::npos ||
               log.find("the job store refused the end of a job") != std::string::npos;
      },
      30))
      << frozen->log();
  ASSERT_TRUE(eventually([&] { return state_of(*c, id) == "succeeded"; }, 180)) << cluster.logs();
  // The unit's film is the run that took it over; the frozen node recorded no end of it.
  EXPECT_NE(cluster.sql("SELECT node FROM tessera_units WHERE job_id = '" + id + "' AND idx = " + idx), owner);
  EXPECT_NE(cluster.sql("SELECT checkpoint_epoch FROM tessera_units WHERE job_id = '" + id + "' AND idx = " + idx),
            stale_epoch);
  std::istringstream lines(frozen->log());
  for (std::string line; std::getline(lines, line);)
    EXPECT_FALSE(line.find("unit done") != std::string::npos &&
                 line.find("\"epoch\":" + stale_epoch + ",") != std::string::npos)
        << "the frozen node recorded the end of its stale run: " << line;
  EXPECT_TRUE(exr_of(*c, id) == reference) << "the EXR differs from the one-node render";
}

}  // namespace
}  // namespace tessera::server::test
