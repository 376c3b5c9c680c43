// Submission checks without HTTP: media type, syntax, schema, then the renderer's semantic checks.
#include <gtest/gtest.h>

#include "server/submission.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using nlohmann::json;

Problem refused(std::string_view type, std::string_view body, SubmissionLimits limits = {}) {
  auto r = check_submission(type, body, limits);
  if (auto* p = std::get_if<Problem>(&r)) return *p;
  ADD_FAILURE() << "accepted: " << body.substr(0, 200);
  return {};
}

TEST(Submission, AcceptsTheCornellBox) {
  auto r = check_submission("application/json; charset=utf-8", test::cornell_job().dump(), {});
  auto* job = std::get_if<AcceptedJob>(&r);
  ASSERT_TRUE(job) << std::get<Problem>(r).detail;
  EXPECT_EQ(job->kind, "scene");
  EXPECT_EQ(job->spp, 256u);
  EXPECT_EQ(job->settings["width"], 512);
  EXPECT_EQ(job->settings["integrator"], "path");
  EXPECT_EQ(job->settings["estimator"], "mis");
  EXPECT_EQ(job->settings["tonemap"], "clamp");
  EXPECT_EQ(job->outputs, json::array({"png", "exr"}));
}

TEST(Submission, RefusesBySyntaxAndType) {
  EXPECT_EQ(refused("text/plain", "{}").status, 415);
  EXPECT_EQ(refused("", "{}").status, 415);
  EXPECT_EQ(refused("application/json", "").status, 400);
  EXPECT_EQ(refused("application/json", "  \n").status, 400);
  EXPECT_EQ(refused("application/json", "{\"kind\": ").status, 400);
  EXPECT_EQ(refused("application/json", "{\"width\": NaN}").status, 400);
  Problem deep = refused("application/json", std::string(10000, '[') + std::string(10000, ']'));
  EXPECT_EQ(deep.status, 422);
}

TEST(Submission, SemanticErrorsNameTheField) {
  json doc = test::cornell_job();
  doc["scene"]["objects"][3]["material"] = "purple";
  Problem p = refused("application/json", doc.dump());
  EXPECT_EQ(p.status, 422);
  EXPECT_EQ(p.pointer, "/scene/objects/3/material");

  doc = test::cornell_job();
  doc["scene"]["objects"][6]["indices"][2] = 8;  // 8 vertices: 0..7
  p = refused("application/json", doc.dump());
  EXPECT_EQ(p.pointer, "/scene/objects/6/indices/2");

  doc = test::cornell_job();
  doc["scene"]["objects"][6]["positions"].erase(0);  // no longer a multiple of 3
  p = refused("application/json", doc.dump());
  EXPECT_EQ(p.pointer, "/scene/objects/6/positions");
}

TEST(Submission, ConfiguredLimitsNameTheField) {
  SubmissionLimits limits;
  limits.render.max_width = 256;
  limits.render.max_spp = 100;
  json doc = test::cornell_job();
  Problem p = refused("application/json", doc.dump(), limits);
  EXPECT_EQ(p.status, 422);
  EXPECT_EQ(p.pointer, "/render/width");
  doc["render"]["width"] = 256;
  doc["render"]["height"] = 256;
  p = refused("application/json", doc.dump(), limits);
  EXPECT_EQ(p.pointer, "/render/spp");
}

}  // namespace
}  // namespace tessera::server
