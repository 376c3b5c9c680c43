// Submission checks without HTTP: media type, syntax, schema, then the renderer's semantic checks.
#include <gtest/gtest.h>

#include "proto/contract.h"
#include "server/jobs/job_json.h"
#include "server/jobs/submission.h"
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
  EXPECT_EQ(job->settings.spp, 256u);
  EXPECT_EQ(job->settings.width, 512);
  EXPECT_EQ(job->settings.integrator.name, "path");
  EXPECT_EQ(job->settings.integrator.estimator, Estimator::kMis);
  EXPECT_EQ(job->settings.display.tonemap, ToneMap::kClamp);
  EXPECT_EQ(job->outputs, OutputSpec{});
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

// One answer tells what can be told: with the schema's errors, the renderer's error on what they leave (an unknown
// material next to a misspelt property and a bad spp); where the renderer's checks cannot run (a required property
// missing), the answer says that they follow.
TEST(Submission, SchemaErrorsComeWithTheRenderersErrorsThatDoNotDependOnThem) {
  json doc = test::cornell_job();
  doc["scene"]["objects"][3]["material"] = "purple";
  doc["render"]["spp"] = 0;
  doc["render"]["spp_"] = 4;
  Problem p = refused("application/json", doc.dump());
  EXPECT_EQ(p.status, 422);
  EXPECT_EQ(p.pointer, "/render/spp");
  ASSERT_EQ(p.errors.size(), 3u) << p.to_json().dump();
  EXPECT_EQ(p.errors[0].first, "/render/spp");
  EXPECT_EQ(p.errors[1].first, "/render/spp_");
  EXPECT_EQ(p.errors[2].first, "/scene/objects/3/material");
  EXPECT_NE(p.errors[2].second.find("purple"), std::string::npos) << p.errors[2].second;
  EXPECT_FALSE(p.pending) << *p.pending;
  EXPECT_EQ(p.to_json()["errors"].size(), 3u);

  // A schema error the renderer's checks would stumble over: they follow, and the answer says so.
  doc = test::cornell_job();
  doc["scene"]["objects"][3]["material"] = "purple";
  doc["scene"]["objects"][0].erase("shape");
  p = refused("application/json", doc.dump());
  ASSERT_TRUE(p.pending) << p.to_json().dump();
  EXPECT_EQ(p.to_json().value("pending", ""),
            "more checks (material names, indices, assets, limits) follow once these errors are fixed");
  for (const auto& [at, what] : p.errors) EXPECT_EQ(what.find("purple"), std::string::npos) << at << ": " << what;

  // Schema errors only, and the renderer finds nothing else: neither an error more nor a pending note.
  doc = test::cornell_job();
  doc["render"]["spp"] = 0;
  p = refused("application/json", doc.dump());
  EXPECT_TRUE(p.errors.size() <= 1) << p.to_json().dump();
  EXPECT_FALSE(p.to_json().contains("pending"));
}

// The status of a job without a time limit or noise target shows none (the README's default, "none"), where it
// showed 0.0; one with them shows them. Both as job-status.schema.json says.
TEST(Submission, AStatusLeavesOutTheStoppingRulesThatAreOff) {
  auto status_of = [](const json& doc) {
    auto r = check_submission("application/json", doc.dump(), {});
    const auto* job = std::get_if<AcceptedJob>(&r);
    EXPECT_TRUE(job) << std::get<Problem>(r).detail;
    JobRecord record;
    record.id = "0123456789abcdef0123456789abcdef";
    record.kind = "scene";
    record.settings = job ? render_settings_text(job->settings) : "{}";
    record.outputs = R"(["png"])";
    const json status = job_status_json(record);
    const auto e = proto::contract_schemas().validate(status, "job-status.schema.json");
    EXPECT_FALSE(e) << e->pointer << " " << e->message;
    return status["render"];
  };
  const json off = status_of(test::cornell_job());
  EXPECT_FALSE(off.contains("time_limit_s")) << off.dump();
  EXPECT_FALSE(off.contains("noise_target")) << off.dump();
  json doc = test::cornell_job();
  doc["render"]["time_limit_s"] = 30;
  doc["render"]["noise_target"] = 0.02;
  const json on = status_of(doc);
  EXPECT_EQ(on.value("time_limit_s", 0.0), 30.0) << on.dump();
  EXPECT_FLOAT_EQ(on.value("noise_target", 0.0), 0.02) << on.dump();  // a float in RenderSettings
}

// Submitted, stored and shown: the status's "render" and "outputs" are what they were before the settings had one
// mapping (captured from that version's check_submission and job_status_json), and the record holds the same text.
TEST(Submission, TheStatusShowsTheSettingsAndOutputsAsBefore) {
  struct Case {
    json render;
    json outputs;  // null: none in the document
    std::string status_render;
    std::string status_outputs;
  };
  const Case cases[] = {
      {json(), json(),
       R"({"estimator":"mis","exposure_ev":0.0,"exr_precision":"half","height":512,"integrator":"path","max_depth":8,)"
       R"("sampler":"sobol","seed":0,"spp":64,"tonemap":"clamp","width":512})",
       R"(["png","exr"])"},
      {{{"width", 640},
        {"height", 360},
        {"spp", 100},
        {"max_depth", 0},
        {"integrator", "bdpt"},
        {"estimator", "hemisphere"},
        {"seed", 9007199254740992ull},
        {"sampler", "independent"},
        {"time_limit_s", 0.3},
        {"noise_target", 0.01},
        {"exposure_ev", 0.1},
        {"tonemap", "aces"},
        {"exr_precision", "float"}},
       {"exr"},
       R"({"estimator":"hemisphere","exposure_ev":0.10000000149011612,"exr_precision":"float","height":360,)"
       R"("integrator":"bdpt","max_depth":0,"noise_target":0.009999999776482582,"sampler":"independent",)"
       R"("seed":9007199254740992,"spp":100,"time_limit_s":0.30000001192092896,"tonemap":"aces","width":640})",
       R"(["exr"])"},
      {{{"estimator", "area"},
        {"integrator", "light"},
        {"exposure_ev", -3.25},
        {"time_limit_s", 600},
        {"noise_target", 1}},
       {"exr", "png"},
       R"({"estimator":"area","exposure_ev":-3.25,"exr_precision":"half","height":512,"integrator":"light",)"
       R"("max_depth":8,"noise_target":1.0,"sampler":"sobol","seed":0,"spp":64,"time_limit_s":600.0,)"
       R"("tonemap":"clamp","width":512})",
       R"(["png","exr"])"},
  };
  for (const Case& c : cases) {
    json doc = test::cornell_job();
    doc.erase("render");
    if (!c.render.is_null()) doc["render"] = c.render;
    if (!c.outputs.is_null()) doc["outputs"] = c.outputs;
    const JobRecord record = test::accepted_job_record(doc);
    EXPECT_EQ(record.outputs, c.status_outputs);
    const json status = job_status_json(record);
    EXPECT_EQ(status["render"].dump(), c.status_render);
    EXPECT_EQ(status["outputs"].dump(), c.status_outputs);
    const auto e = proto::contract_schemas().validate(status, "job-status.schema.json");
    EXPECT_FALSE(e) << e->pointer << " " << e->message;
  }
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

// render.denoise: a name the contract lists, and one the integrator can feed (the denoiser reads the variance pass,
// which bdpt cannot make); its features count in the film's size.
TEST(Submission, RefusesADenoiserByName) {
  json doc = test::cornell_job();
  doc["render"]["denoise"] = "nfor";
  Problem p = refused("application/json", doc.dump());
  EXPECT_EQ(p.status, 422);
  EXPECT_EQ(p.pointer, "/render/denoise");

  doc["render"]["denoise"] = "regression";
  doc["render"]["integrator"] = "bdpt";
  p = refused("application/json", doc.dump());
  EXPECT_EQ(p.status, 422);
  EXPECT_EQ(p.pointer, "/render/denoise");
  EXPECT_NE(p.detail.find("variance"), std::string::npos) << p.detail;

  doc["render"]["integrator"] = "path";
  auto r = check_submission("application/json", doc.dump(), {});
  ASSERT_TRUE(std::get_if<AcceptedJob>(&r)) << std::get<Problem>(r).detail;
  EXPECT_EQ(std::get<AcceptedJob>(r).settings.denoise, Denoiser::kRegression);

  // 512 x 512: 56 bytes a pixel for the beauty, 164 for the features.
  SubmissionLimits limits;
  limits.max_film_bytes = 512 * 512 * 100;
  EXPECT_EQ(refused("application/json", doc.dump(), limits).status, 422);
  doc["render"].erase("denoise");
  r = check_submission("application/json", doc.dump(), limits);
  EXPECT_TRUE(std::get_if<AcceptedJob>(&r));
}

// A material job previews with adaptive sampling and the denoiser unless its document sets them; the settings hold
// them explicitly, so the record's text keeps them whatever the defaults become. A scene job keeps both off, and an
// integrator that can do neither (bdpt) previews without them rather than being refused.
TEST(Submission, AMaterialJobPreviewsAdaptiveAndDenoisedUnlessItSaysOtherwise) {
  const json material = {{"kind", "material"}, {"material", {{"type", "lambert"}}}};
  auto accepted = [](const json& doc) {
    auto r = check_submission("application/json", doc.dump(), {});
    if (auto* job = std::get_if<AcceptedJob>(&r)) return *job;
    ADD_FAILURE() << doc.dump() << ": " << std::get<Problem>(r).detail;
    return AcceptedJob{};
  };
  const AcceptedJob preview = accepted(material);
  EXPECT_FLOAT_EQ(preview.settings.adaptive_threshold, kPreviewAdaptiveThreshold);
  EXPECT_EQ(preview.settings.denoise, Denoiser::kRegression);
  const RenderSettings stored = render_settings_from_text(render_settings_text(preview.settings));
  EXPECT_FLOAT_EQ(stored.adaptive_threshold, kPreviewAdaptiveThreshold);
  EXPECT_EQ(stored.denoise, Denoiser::kRegression);

  json explicit_off = material;
  explicit_off["render"] = {{"adaptive_threshold", 0}, {"denoise", "none"}, {"spp", 32}};
  const AcceptedJob off = accepted(explicit_off);
  EXPECT_EQ(off.settings.adaptive_threshold, 0);
  EXPECT_EQ(off.settings.denoise, Denoiser::kNone);
  EXPECT_EQ(off.settings.spp, 32u);
  EXPECT_EQ(render_settings_from_text(render_settings_text(off.settings)).adaptive_threshold, 0);

  json bdpt = material;
  bdpt["render"] = {{"integrator", "bdpt"}};
  const AcceptedJob splatting = accepted(bdpt);
  EXPECT_EQ(splatting.settings.adaptive_threshold, 0);
  EXPECT_EQ(splatting.settings.denoise, Denoiser::kNone);

  const AcceptedJob scene = accepted(test::cornell_job());
  EXPECT_EQ(scene.settings.adaptive_threshold, 0);
  EXPECT_EQ(scene.settings.denoise, Denoiser::kNone);
}

// render.shutter: open and close within 10 frames of the frame (a number that is not finite is not JSON: 400; the
// renderer's reader refuses one, RenderSettings.AShutterIsReadAndRefusedNamingTheField), open not after close, steps
// within Embree's; each refusal a 422 naming the field. A good shutter is taken, and its steps default to 2.
TEST(Submission, RefusesABadShutterNamingTheField) {
  struct Case {
    json shutter;
    const char* pointer;
  };
  const Case cases[] = {
      {{{"open", 0.25}, {"close", -0.25}}, "/render/shutter/close"},  // open after close
      {{{"open", -20}, {"close", 0.25}}, "/render/shutter/open"},     // wider than the limit
      {{{"open", -0.25}, {"close", 0.25}, {"steps", 1}}, "/render/shutter/steps"},
      {{{"open", -0.25}, {"close", 0.25}, {"steps", 1000}}, "/render/shutter/steps"},
      {{{"open", "-0.25"}, {"close", 0.25}}, "/render/shutter/open"},
      {{{"open", -0.25}}, "/render/shutter/close"},
      {-0.25, "/render/shutter"},
  };
  for (const Case& c : cases) {
    json doc = test::cornell_job();
    doc["render"]["shutter"] = c.shutter;
    const Problem p = refused("application/json", doc.dump());
    EXPECT_EQ(p.status, 422) << c.shutter.dump();
    EXPECT_EQ(p.pointer, c.pointer) << c.shutter.dump() << ": " << p.detail;
  }
  json doc = test::cornell_job();
  doc["render"]["shutter"] = {{"open", -0.25}, {"close", 0.25}};
  auto r = check_submission("application/json", doc.dump(), {});
  ASSERT_TRUE(std::get_if<AcceptedJob>(&r)) << std::get<Problem>(r).detail;
  const RenderSettings& settings = std::get<AcceptedJob>(r).settings;
  ASSERT_TRUE(settings.shutter);
  EXPECT_EQ(*settings.shutter, (Shutter{-0.25, 0.25, 2}));
  EXPECT_EQ(render_settings_from_text(render_settings_text(settings)), settings);
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
