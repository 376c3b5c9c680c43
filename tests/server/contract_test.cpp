// The server and its contract agree: every route is in the OpenAPI document and every path there is served; the
// documents the server produces validate against the schemas it publishes.
#include <gtest/gtest.h>

#include <set>
#include <string>
#include <vector>

#include "proto/contract.h"
#include "server/base/job_id.h"
#include "server/base/problem.h"
#include "server/http/http_api.h"
#include "server/http/web_files.h"
#include "server/jobs/job_json.h"
#include "server/jobs/materials_catalog.h"

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
  // A refused document's every error, and the checks that follow once they are fixed.
  Problem many{422, "must be at least 1", std::string("/render/spp")};
  many.errors = {{"/render/spp", "must be at least 1"}, {"/scene/objects/0", "missing property \"shape\""}};
  many.pending = std::string(proto::kChecksPending);
  auto e = proto::contract_schemas().validate(many.to_json(), "problem.schema.json");
  EXPECT_FALSE(e) << e->pointer << " " << e->message;
  EXPECT_EQ(many.to_json().value("pending", ""), proto::kChecksPending);
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

// A frame range's status: its frames by state as ranges of frame numbers, merged across consecutive units and
// bounded (a list of more than 64 ranges is cut and says so), its frames' result links, and no job-wide result link.
TEST(Contract, AFrameRangesStatusListsItsFramesAsBoundedRanges) {
  JobRecord r;
  r.id = new_job_id();
  r.kind = "scene";
  r.state = JobState::kRunning;
  r.created_at_ms = 1714560000000;
  r.started_at_ms = r.created_at_ms;
  r.settings = R"({"width":64,"height":36,"spp":2,"max_depth":8,"integrator":"path","estimator":"mis","seed":1,)"
               R"("frames":{"start":10,"end":10008,"step":2,"chunk":1}})";
  r.outputs = R"(["png","exr"])";
  r.progress.samples_total = 2 * 5000;
  // 5000 units: every third done, unit 1 running, the rest waiting.
  std::vector<UnitRecord> units(5000);
  for (int i = 0; i < 5000; ++i) {
    units[static_cast<size_t>(i)].index = i;
    units[static_cast<size_t>(i)].samples = 2;
    units[static_cast<size_t>(i)].done = i % 3 == 0 || i < 4;
  }
  units[4].done = false;
  units[4].running = true;
  units[4].node = "n1";
  json status = job_status_json(r, std::nullopt, std::nullopt, units, r.created_at_ms + 1000);
  auto e = proto::contract_schemas().validate(status, "job-status.schema.json");
  EXPECT_FALSE(e) << e->pointer << " " << e->message;
  const json& frames = status["frames"];
  EXPECT_EQ(frames["total"], 5000);
  EXPECT_EQ(frames["running"], 1);
  EXPECT_EQ(frames["running_ranges"], json::parse("[[18, 18]]"));
  EXPECT_EQ(frames["done_ranges"][0], json::parse("[10, 16]"));  // units 0-3: frames 10, 12, 14, 16
  EXPECT_EQ(frames["done_ranges"].size(), 64u);
  EXPECT_EQ(frames["ranges_truncated"], true);
  EXPECT_EQ(frames["last_done"], 10 + 2 * 4998);
  EXPECT_EQ(frames["links"]["result_exr"], "/v1/jobs/" + r.id + "/frames/{frame}/result.exr");
  EXPECT_LT(status.dump().size(), 4096u);
  // Failed: the unit that was running is the frame that failed.
  r.state = JobState::kFailed;
  status = job_status_json(r, std::nullopt, std::nullopt, units, r.created_at_ms + 1000);
  EXPECT_EQ(status["frames"]["failed_ranges"], json::parse("[[18, 18]]"));
  EXPECT_FALSE(status["links"].contains("result_exr"));
}

// A split job one of whose nodes stopped renewing its unit's lease: the status says which unit waits, and for how
// long, and its ETA counts that wait and the unit's rest at the rate it rendered, where the store's ETA (from the
// rates of the units running) did not.
TEST(Contract, AStalledUnitShowsItsTakeoverAndItsWaitIsInTheEta) {
  JobRecord r;
  r.id = new_job_id();
  r.kind = "scene";
  r.state = JobState::kRunning;
  r.created_at_ms = 1714560000000;
  r.started_at_ms = r.created_at_ms;
  r.settings = R"({"width":64,"height":64,"spp":64,"max_depth":8,"integrator":"path","estimator":"mis","seed":1})";
  r.outputs = R"(["png","exr"])";
  r.progress.samples_total = 64;
  r.progress.samples_done = 60;
  r.progress.eta_s = 1.5;  // the store's, from the stalled unit's last rate
  const int64_t now = r.created_at_ms + 60000;
  std::vector<UnitRecord> units(2);
  units[0].index = 0;
  units[0].samples = 32;
  units[0].done = true;
  units[0].node = "n1";
  units[1].index = 1;
  units[1].first_sample = 32;
  units[1].samples = 32;
  units[1].running = true;
  units[1].node = "n2";
  units[1].samples_done = 28;
  units[1].elapsed_s = 56;  // 2 s a sample per pixel: 4 left, 8 s
  // Its lease of 30 s was last renewed 10 s ago: 20 s to wait.
  units[1].renewed_at_ms = now - 10000;
  units[1].lease_expires_at_ms = units[1].renewed_at_ms + 30000;
  json status = job_status_json(r, std::nullopt, std::nullopt, units, now);
  auto e = proto::contract_schemas().validate(status, "job-status.schema.json");
  EXPECT_FALSE(e) << e->pointer << " " << e->message;
  const json& running = status["units"]["running"];
  ASSERT_EQ(running.size(), 1u) << status["units"];
  EXPECT_EQ(running[0]["stalled"], true);
  EXPECT_DOUBLE_EQ(running[0]["takeover_in_s"].get<double>(), 20.0);
  EXPECT_DOUBLE_EQ(status["progress"]["eta_s"].get<double>(), 28.0);

  // Renewed a second ago: rendering, and the store's ETA stands.
  units[1].renewed_at_ms = now - 1000;
  units[1].lease_expires_at_ms = units[1].renewed_at_ms + 30000;
  status = job_status_json(r, std::nullopt, std::nullopt, units, now);
  e = proto::contract_schemas().validate(status, "job-status.schema.json");
  EXPECT_FALSE(e) << e->pointer << " " << e->message;
  EXPECT_EQ(status["units"]["running"][0]["stalled"], false);
  EXPECT_TRUE(status["units"]["running"][0]["takeover_in_s"].is_null());
  EXPECT_DOUBLE_EQ(status["progress"]["eta_s"].get<double>(), 1.5);
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

// Parameters come in the order the schema file gives them, not sorted by name (nlohmann::json sorts an object's
// members): a conductor's roughness comes right after its distribution, before the anisotropic overrides.
TEST(Contract, MaterialCatalogKeepsTheSchemasOrder) {
  const json catalog = describe_materials(proto::contract_schemas());
  for (const json& m : catalog.at("materials")) {
    if (m.at("type") != "conductor") continue;
    std::vector<std::string> names;
    for (const json& p : m.at("parameters")) names.push_back(p.at("name"));
    ASSERT_GE(names.size(), 6u);
    EXPECT_EQ(std::vector<std::string>(names.begin(), names.begin() + 6),
              (std::vector<std::string>{"distribution", "roughness", "alpha_x", "alpha_y", "metal", "eta"}));
    return;
  }
  FAIL() << "no conductor in the catalogue";
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

// Browsers ask for /favicon.ico whatever the page links: it is the page's SVG icon, served as one. examples.json holds
// the example jobs of proto/examples, each a valid job.
TEST(Contract, WebClientHasItsIconAndTheExamples) {
  auto icon = web_file("favicon.ico");
  ASSERT_TRUE(icon);
  EXPECT_EQ(*icon, web_file("favicon.svg").value_or(""));
  EXPECT_EQ(web_media_type("favicon.ico"), "image/svg+xml");
  EXPECT_EQ(web_media_type("app.js"), "text/javascript; charset=utf-8");
  auto text = web_file("examples.json");
  ASSERT_TRUE(text);
  const json examples = json::parse(*text);
  EXPECT_TRUE(examples.contains("cornell.json")) << examples.dump();
  for (const auto& [name, job] : examples.items()) {
    auto e = proto::contract_schemas().validate(job, "job.schema.json");
    EXPECT_FALSE(e) << name << ": " << e->pointer << " " << e->message;
  }
}

}  // namespace
}  // namespace tessera::server
