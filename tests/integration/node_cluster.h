// Three tesserad (n1, n2, n3) sharing one throw-away PostgreSQL database (postgres_cluster.h) and one data directory,
// with leases of 2 s and one render thread each, for the cluster tests.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "tests/integration/daemon.h"
#include "tests/server/postgres_cluster.h"
#include "tests/server/test_util.h"

namespace tessera::server::test {

class NodeCluster {
 public:
  // `extra`: more arguments for every node.
  explicit NodeCluster(const std::vector<std::string>& extra = {})
      : pg_(PostgresCluster::shared()), uri_(pg_.create_database()) {
    for (const char* name : {"n1", "n2", "n3"}) {
      std::vector<std::string> args = {"--store", uri_, "--node", name, "--lease-s", "2", "--threads", "1"};
      args.insert(args.end(), extra.begin(), extra.end());
      nodes_.push_back(std::make_unique<Daemon>(dir_.path() / "shared", args));
    }
  }
  Daemon& node(int i) { return *nodes_[i]; }
  std::string sql(const std::string& query) { return pg_.psql(PostgresCluster::database_of(uri_), query); }
  std::string logs() {
    std::string out;
    for (auto& n : nodes_)
      if (n) out += n->log();
    return out;
  }

 private:
  TempDir dir_;
  PostgresCluster& pg_;
  std::string uri_;
  std::vector<std::unique_ptr<Daemon>> nodes_;
};

}  // namespace tessera::server::test
