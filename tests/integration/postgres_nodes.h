// What the tests of daemons sharing one PostgreSQL store do with them: submit a job, read its state through a node,
// read its row in the database.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "tests/integration/daemon.h"
#include "tests/server/postgres_cluster.h"

namespace tessera::server::test {

inline std::string submit(httplib::Client& c, const nlohmann::json& doc) {
  auto res = c.Post("/v1/jobs", doc.dump(), "application/json");
  if (!res || res->status != 202) {
    ADD_FAILURE() << "submission refused: " << (res ? res->body : "no answer");
    return "";
  }
  return nlohmann::json::parse(res->body).value("id", "");
}

inline std::string state_of(httplib::Client& c, const std::string& id) {
  auto res = c.Get("/v1/jobs/" + id);
  return res && res->status == 200 ? nlohmann::json::parse(res->body).value("state", "") : "";
}

// `columns` (an SQL expression list) of the job's row.
inline std::string row_of(PostgresCluster& pg, const std::string& uri, const std::string& id,
                          const std::string& columns) {
  return pg.psql(PostgresCluster::database_of(uri), "SELECT " + columns + " FROM tessera_jobs WHERE id = '" + id + "'");
}

}  // namespace tessera::server::test
