// The server and its contract agree: every route is in the OpenAPI document and every path there is served; the
// documents the server produces validate against the schemas it publishes.
#include <gtest/gtest.h>

#include <set>

#include "proto/contract.h"
#include "server/http_api.h"
#include "server/job_id.h"
#include "server/job_json.h"
#include "server/materials_catalog.h"
#include "server/problem.h"
#include "server/web_files.h"

namespace tessera::server {
namespace {

using nlohmann::json;

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

TEST(Contract, RoutesAndOpenApiAgree) {
  const json openapi = json::parse(proto::openapi_json());
  EXPECT_EQ(openapi.value("openapi", ""), "3.1.0");
  std::set<std::pair<std::string, std::string>> served, documented;
  for (const RouteInfo& r : api_routes()) served.insert({lower(r.method), r.path});
  for (const auto& [path, item] : openapi.at("paths").items())
    for (const auto& [method, op] : item.items())
      if (method != "parameters") documented.insert({method, path});
  EXPECT_EQ(served, documented);
}

TEST(Contract, OpenApiReferencesResolve) {
  const json openapi = json::parse(proto::openapi_json());
  std::function<void(const json&)> walk = [&](const json& v) {
    if (v.is_object()) {
      for (const auto& [k, sub] : v.items()) {
        if (k == "$ref" && sub.is_string()) {
          const std::string ref = sub.get<std::string>();
          if (ref.rfind("#/", 0) == 0) {
            EXPECT_TRUE(openapi.contains(json::json_pointer(ref.substr(1)))) << ref;
          } else {
            const std::string file = ref.substr(0, ref.find('#'));
            ASSERT_EQ(file.rfind("schemas/", 0), 0u) << ref;
            std::string target;
            EXPECT_NE(proto::contract_schemas().resolve("", ref.substr(8), &target), nullptr) << ref;
          }
        } else {
          walk(sub);
        }
      }
    } else if (v.is_array()) {
      for (const json& sub : v) walk(sub);
    }
  };
  walk(openapi);
}

TEST(Contract, ProblemsMatchTheirSchema) {
  for (int status : {400, 404, 405, 409, 413, 415, 422, 500, 503, 507}) {
    Problem p{status, "something", std::string("/render/width")};
    auto e = proto::contract_schemas().validate(p.to_json(), "problem.schema.json");
    EXPECT_FALSE(e) << status << ": " << e->pointer << " " << e->message;
    EXPECT_FALSE(p.title().empty());
  }
  const Problem full{507, "", std::nullopt};
  EXPECT_EQ(full.type(), "https://tessera.dev/problems/insufficient-storage");
  EXPECT_EQ(full.title(), "Insufficient storage");
}

TEST(Contract, JobStatusMatchesItsSchema) {
  JobRecord r;
  r.id = new_job_id();
  r.kind = "scene";
  r.created_at_ms = 1714560000123;
  r.settings = R"({"width":64,"height":64,"spp":16,"max_depth":8,"integrator":"path","estimator":"mis","seed":1})";
  r.outputs = R"(["png","exr"])";
  r.progress.samples_total = 16;
  json queued = job_status_json(r);
  auto e = proto::contract_schemas().validate(queued, "job-status.schema.json");
  EXPECT_FALSE(e) << e->pointer << " " << e->message;
  EXPECT_EQ(queued["created_at"], "2024-05-01T10:40:00.123Z");
  EXPECT_TRUE(queued["progress"]["eta_s"].is_null());

  r.state = JobState::kSucceeded;
  r.started_at_ms = r.created_at_ms + 10;
  r.finished_at_ms = r.created_at_ms + 2000;
  r.progress.passes = 5;
  r.progress.samples_done = 16;
  r.progress.eta_s = 0;
  r.stop_reason = "samples";
  json done = job_status_json(r);
  e = proto::contract_schemas().validate(done, "job-status.schema.json");
  EXPECT_FALSE(e) << e->pointer << " " << e->message;
  EXPECT_EQ(done["links"]["result_exr"], "/v1/jobs/" + r.id + "/result.exr");
  EXPECT_EQ(done["progress"]["fraction"], 1.0);
}

TEST(Contract, MaterialCatalogComesFromTheSchema) {
  const json catalog = describe_materials(proto::contract_schemas());
  std::map<std::string, json> by_type;
  for (const json& m : catalog.at("materials")) by_type[m.at("type")] = m;
  ASSERT_TRUE(by_type.count("lambert"));
  ASSERT_TRUE(by_type.count("emission"));
  const json& lambert = by_type["lambert"];
  EXPECT_EQ(lambert["title"], "Lambert");
  bool found = false;
  for (const json& p : lambert["parameters"]) {
    if (p["name"] != "albedo") continue;
    found = true;
    EXPECT_EQ(p["default"], json::array({0.8, 0.8, 0.8}));
    EXPECT_EQ(p["minimum"], 0);
    EXPECT_EQ(p["maximum"], 1);
    EXPECT_TRUE(p["schema"].contains("anyOf"));  // the $ref was resolved
  }
  EXPECT_TRUE(found);
  // Every model the schema's type enum names is described.
  const json* material = proto::contract_schemas().document("material.schema.json");
  for (const json& t : material->at("/properties/type/enum"_json_pointer))
    EXPECT_TRUE(by_type.count(t.get<std::string>())) << t;
}

TEST(Contract, WebClientIsEmbedded) {
  auto page = web_file("index.html");
  ASSERT_TRUE(page);
  // The page or one of the scripts it loads talks to the API.
  bool uses_api = page->find("/v1/jobs") != std::string::npos;
  for (const char* f : {"app.js", "api.js"})
    if (auto s = web_file(f)) uses_api = uses_api || s->find("/v1/jobs") != std::string::npos;
  EXPECT_TRUE(uses_api);
}

}  // namespace
}  // namespace tessera::server
