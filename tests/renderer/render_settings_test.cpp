// The render settings' and outputs' one JSON mapping (renderer/render_settings.h): documents read to the settings
// they say, the normalised form reads back to the same settings, and the text job records hold reads as before.
#include "renderer/render_settings.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>

#include "renderer/scene_error.h"

namespace tessera {
namespace {

using nlohmann::json;

RenderSettings read(const json& render) {
  return render_settings_from_json(render, "/render", RenderLimits{});
}

// Every field a document can set, none at its default.
const json kEveryField = {{"width", 640},
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
                          {"exr_precision", "float"}};

// document -> settings -> JSON -> settings gives the same settings, and the JSON is the same again.
void expect_round_trip(const json& render) {
  const RenderSettings first = read(render);
  const json normalised = render_settings_to_json(first);
  const RenderSettings second = read(normalised);
  EXPECT_EQ(first, second) << render.dump() << " -> " << normalised.dump();
  EXPECT_EQ(render_settings_to_json(second), normalised) << render.dump();
}

TEST(RenderSettingsMapping, EveryFieldRoundTrips) {
  expect_round_trip(json());  // no "render": every default
  expect_round_trip(json::object());
  expect_round_trip(kEveryField);
  // Each field of kEveryField alone moves the settings off their defaults, so the round trip above covers it.
  for (const auto& [key, value] : kEveryField.items()) {
    EXPECT_NE(read(json{{key, value}}), RenderSettings{}) << key;
    expect_round_trip(json{{key, value}});
  }
  // Every name of every enumeration.
  for (const char* name : {"sobol", "independent"}) expect_round_trip({{"sampler", name}});
  for (const char* name : {"mis", "area", "hemisphere"}) expect_round_trip({{"estimator", name}});
  for (const char* name : {"clamp", "aces"}) expect_round_trip({{"tonemap", name}});
  for (const char* name : {"half", "float"}) expect_round_trip({{"exr_precision", name}});
  for (const std::string& name : IntegratorRegistry::builtin().names()) expect_round_trip({{"integrator", name}});
  // Numbers at the ends of their ranges, and integers written as floats.
  expect_round_trip({{"width", 8192}, {"height", 1}, {"spp", 65536}, {"max_depth", 1024}, {"seed", 0}});
  expect_round_trip({{"width", 6.4e2}, {"spp", 1e1}, {"exposure_ev", -20}, {"time_limit_s", 604800}});
  expect_round_trip({{"exposure_ev", 20}, {"noise_target", 1}, {"time_limit_s", 1e-7}});
}

TEST(RenderSettingsMapping, TheNormalisedFormIsTheSchemasFieldsAndDefaults) {
  std::ifstream in("proto/schemas/render.schema.json");
  ASSERT_TRUE(in) << "run from the source tree";
  const json properties = json::parse(in)["properties"];
  // max_volume_depth, subsurface_guiding, aovs, denoise and fps are left out at their defaults (the stored records'
  // text, below), written otherwise; frames and shutter, which have no default (a still, no blur), are written only
  // when set.
  RenderSettings deep;
  deep.integrator.max_volume_depth = 7;
  EXPECT_EQ(render_settings_to_json(deep).value("max_volume_depth", 0), 7);
  json normalised = render_settings_to_json(RenderSettings{});
  EXPECT_FALSE(normalised.contains("max_volume_depth"));
  EXPECT_FALSE(normalised.contains("aovs"));
  EXPECT_FALSE(normalised.contains("denoise"));
  EXPECT_FALSE(normalised.contains("adaptive_threshold"));
  EXPECT_FALSE(normalised.contains("min_spp"));
  EXPECT_FALSE(normalised.contains("subsurface_guiding"));
  normalised["max_volume_depth"] = RenderSettings{}.integrator.max_volume_depth;
  normalised["subsurface_guiding"] = true;
  normalised["aovs"] = json::array();
  normalised["denoise"] = "none";
  EXPECT_FALSE(normalised.contains("fps"));
  EXPECT_FALSE(normalised.contains("frames"));
  EXPECT_FALSE(normalised.contains("shutter"));
  normalised["fps"] = kDefaultFps;
  normalised["adaptive_threshold"] = 0.0;
  normalised["min_spp"] = 16;
  EXPECT_FALSE(properties["frames"].contains("default"));
  EXPECT_FALSE(properties["shutter"].contains("default"));
  EXPECT_EQ(normalised.size() + 2, properties.size()) << normalised.dump();
  for (const auto& [key, property] : properties.items()) {
    if (key == "frames" || key == "shutter") continue;
    ASSERT_TRUE(normalised.contains(key)) << key;
    EXPECT_EQ(normalised[key], property["default"]) << key;
  }
}

TEST(RenderSettingsMapping, RefusalsNameTheFieldAndTheNames) {
  auto refusal = [](const json& render) -> std::pair<std::string, std::string> {
    try {
      read(render);
    } catch (const SceneError& e) {
      return {e.pointer(), e.what()};
    }
    return {"accepted", render.dump()};
  };
  using P = std::pair<std::string, std::string>;
  EXPECT_EQ(refusal({{"estimator", "mist"}}), P("/render/estimator", "must be \"mis\", \"area\" or \"hemisphere\""));
  EXPECT_EQ(refusal({{"sampler", 1}}), P("/render/sampler", "must be \"sobol\" or \"independent\""));
  EXPECT_EQ(refusal({{"tonemap", "filmic"}}), P("/render/tonemap", "must be \"clamp\" or \"aces\""));
  EXPECT_EQ(refusal({{"exr_precision", "double"}}), P("/render/exr_precision", "must be \"half\" or \"float\""));
  EXPECT_EQ(refusal({{"width", 0}}), P("/render/width", "must be between 1 and 8192"));
  EXPECT_EQ(refusal({{"exposure_ev", 21}}), P("/render/exposure_ev", "must be at least -20.0 and at most 20.0"));
  EXPECT_EQ(refusal(json::array()), P("/render", "must be an object"));
  // The server's own limits, where they are lower than the contract's.
  RenderLimits limits;
  limits.max_spp = 100;
  EXPECT_THROW(render_settings_from_json({{"spp", 101}}, "/render", limits), SceneError);
}

// render.shutter: read with its steps' default, written back only when set, refused naming the field where open is
// after close, a value is not a finite number or further than 10 frames from the frame, or the steps are not 2 to 129.
TEST(RenderSettingsMapping, AShutterIsReadAndRefusedNamingTheField) {
  const RenderSettings blurred = read({{"shutter", {{"open", -0.25}, {"close", 0.25}}}});
  ASSERT_TRUE(blurred.shutter);
  EXPECT_EQ(*blurred.shutter, (Shutter{-0.25, 0.25, 2}));
  expect_round_trip({{"shutter", {{"open", -0.25}, {"close", 0.25}}}});
  expect_round_trip({{"shutter", {{"open", 0}, {"close", 1}, {"steps", 8}}}});
  EXPECT_FALSE(render_settings_to_json(read(json::object())).contains("shutter"));
  auto refused_at = [](const json& shutter) {
    try {
      read({{"shutter", shutter}});
    } catch (const SceneError& e) {
      return e.pointer();
    }
    return std::string("accepted");
  };
  EXPECT_EQ(refused_at({{"open", 0.5}, {"close", 0.25}}), "/render/shutter/close");
  EXPECT_EQ(refused_at({{"open", -0.25}, {"close", std::numeric_limits<double>::infinity()}}), "/render/shutter/close");
  EXPECT_EQ(refused_at({{"open", std::nan("")}, {"close", 0.25}}), "/render/shutter/open");
  EXPECT_EQ(refused_at({{"open", -11}, {"close", 0.25}}), "/render/shutter/open");
  EXPECT_EQ(refused_at({{"open", 0}, {"close", 0.25}, {"steps", 130}}), "/render/shutter/steps");
  EXPECT_EQ(refused_at({{"close", 0.25}}), "/render/shutter/open");
  EXPECT_EQ(refused_at("fast"), "/render/shutter");
  // The steps' times, in seconds relative to the frame's: evenly spread from open to close at the frames' rate.
  const std::vector<double> times = shutter_step_times(Shutter{-0.5, 0.5, 3}, 2);
  ASSERT_EQ(times.size(), 3u);
  EXPECT_DOUBLE_EQ(times[0], -0.25);
  EXPECT_DOUBLE_EQ(times[1], 0);
  EXPECT_DOUBLE_EQ(times[2], 0.25);
}

TEST(RenderSettingsMapping, AdaptiveSamplingRoundTripsAndIsWrittenOnlyWhereSet) {
  expect_round_trip({{"adaptive_threshold", 0.01}});
  expect_round_trip({{"adaptive_threshold", 1}, {"min_spp", 4}});
  expect_round_trip({{"adaptive_threshold", 0.05}, {"spp", 1000}, {"min_spp", 1000}});
  EXPECT_EQ(read({{"adaptive_threshold", 0.01}}).adaptive_threshold, static_cast<double>(0.01f));
  // min_spp: 16 by default, spp when that is fewer; written only where it is not its default.
  EXPECT_EQ(read(json::object()).min_spp, 16u);
  EXPECT_EQ(read({{"spp", 8}}).min_spp, 8u);
  EXPECT_FALSE(render_settings_to_json(read({{"spp", 8}})).contains("min_spp"));
  EXPECT_EQ(render_settings_to_json(read({{"min_spp", 32}})).value("min_spp", 0), 32);
  EXPECT_EQ(render_settings_to_json(read({{"adaptive_threshold", 0.5}})).value("adaptive_threshold", 0.0), 0.5);
  // Any integrator takes the threshold 0 (off).
  EXPECT_EQ(read({{"integrator", "bdpt"}, {"adaptive_threshold", 0}}).adaptive_threshold, 0);
}

TEST(RenderSettingsMapping, AdaptiveSamplingOutOfRangeOrWithALightPathIntegratorIsRefusedAtItsField) {
  auto pointer = [](const json& render) -> std::string {
    try {
      read(render);
    } catch (const SceneError& e) {
      return e.pointer();
    }
    return "accepted";
  };
  EXPECT_EQ(pointer({{"adaptive_threshold", -0.01}}), "/render/adaptive_threshold");
  EXPECT_EQ(pointer({{"adaptive_threshold", 1.5}}), "/render/adaptive_threshold");
  EXPECT_EQ(pointer({{"adaptive_threshold", "0.01"}}), "/render/adaptive_threshold");
  EXPECT_EQ(pointer({{"adaptive_threshold", nullptr}}), "/render/adaptive_threshold");
  EXPECT_EQ(pointer({{"min_spp", 0}}), "/render/min_spp");
  EXPECT_EQ(pointer({{"min_spp", 65}}), "/render/min_spp");  // above the default spp, 64
  EXPECT_EQ(pointer({{"spp", 100}, {"min_spp", 101}}), "/render/min_spp");
  EXPECT_EQ(pointer({{"min_spp", 2.5}}), "/render/min_spp");
  EXPECT_EQ(pointer({{"spp", 100}, {"min_spp", 100}}), "accepted");
  for (const char* integrator : {"bdpt", "light"}) {
    EXPECT_EQ(pointer({{"integrator", integrator}, {"adaptive_threshold", 0.01}}), "/render/adaptive_threshold");
    try {
      read({{"integrator", integrator}, {"adaptive_threshold", 0.01}});
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("splat"), std::string::npos) << e.what();
    }
  }
}

TEST(OutputSpecMapping, EveryChoiceRoundTripsInItsNormalisedOrder) {
  for (const json& outputs : {json{"png"}, json{"exr"}, json{"png", "exr"}}) {
    const OutputSpec spec = output_spec_from_json(outputs, "/outputs");
    EXPECT_EQ(output_spec_to_json(spec), outputs);
    EXPECT_EQ(output_spec_from_json(output_spec_to_json(spec), "/outputs"), spec);
  }
  EXPECT_EQ(output_spec_to_json(output_spec_from_json({"exr", "png"}, "/outputs")), json({"png", "exr"}));
  EXPECT_EQ(output_spec_to_json(OutputSpec{}), json({"png", "exr"}));  // the document's default
  for (const auto& [outputs, pointer] : {std::pair<json, std::string>{json::array(), "/outputs"},
                                         {json("png"), "/outputs"},
                                         {json{"png", "gif"}, "/outputs/1"}}) {
    try {
      output_spec_from_json(outputs, "/outputs");
      ADD_FAILURE() << "accepted " << outputs.dump();
    } catch (const SceneError& e) {
      EXPECT_EQ(e.pointer(), pointer) << outputs.dump();
    }
  }
}

// What job records hold: the text the server wrote for these documents' "render" and "outputs" before the mapping
// was one (captured from that version's check_submission). It reads to the settings the document says, and the
// mapping writes it again byte for byte: a record's checkpoints are fingerprinted with the text (FNV-1a), so a job
// stored then and one stored now of the same document share their fingerprints.
TEST(StoredSettings, TheTextRecordsHoldReadsToTheSameSettingsAndIsWrittenAgainByteForByte) {
  struct Case {
    json render;
    std::string text;
  };
  const Case cases[] = {
      {json(),
       R"({"estimator":"mis","exposure_ev":0.0,"exr_precision":"half","height":512,"integrator":"path","max_depth":8,)"
       R"("noise_target":0.0,"sampler":"sobol","seed":0,"spp":64,"time_limit_s":0.0,"tonemap":"clamp","width":512})"},
      {kEveryField,
       R"({"estimator":"hemisphere","exposure_ev":0.10000000149011612,"exr_precision":"float","height":360,)"
       R"("integrator":"bdpt","max_depth":0,"noise_target":0.009999999776482582,"sampler":"independent",)"
       R"("seed":9007199254740992,"spp":100,"time_limit_s":0.30000001192092896,"tonemap":"aces","width":640})"},
      {{{"estimator", "area"},
        {"integrator", "light"},
        {"exposure_ev", -3.25},
        {"time_limit_s", 600},
        {"noise_target", 1}},
       R"({"estimator":"area","exposure_ev":-3.25,"exr_precision":"half","height":512,"integrator":"light",)"
       R"("max_depth":8,"noise_target":1.0,"sampler":"sobol","seed":0,"spp":64,"time_limit_s":600.0,)"
       R"("tonemap":"clamp","width":512})"},
      {{{"width", 6.4e2}, {"height", 4.8e2}, {"spp", 1e1}, {"seed", 1e3}},
       R"({"estimator":"mis","exposure_ev":0.0,"exr_precision":"half","height":480,"integrator":"path","max_depth":8,)"
       R"("noise_target":0.0,"sampler":"sobol","seed":1000,"spp":10,"time_limit_s":0.0,"tonemap":"clamp",)"
       R"("width":640})"},
  };
  for (const Case& c : cases) {
    const RenderSettings settings = read(c.render);
    EXPECT_EQ(render_settings_from_text(c.text), settings) << c.text;
    EXPECT_EQ(render_settings_text(settings), c.text);
  }
  // A key added since is written only when it is not its default, and then round-trips.
  const RenderSettings deep = read({{"max_volume_depth", 1000}});
  EXPECT_EQ(deep.integrator.max_volume_depth, 1000);
  EXPECT_EQ(render_settings_from_text(render_settings_text(deep)), deep);
  EXPECT_EQ(render_settings_text(read(json())).find("max_volume_depth"), std::string::npos);
  for (const char* text : {R"(["png","exr"])", R"(["png"])", R"(["exr"])"})
    EXPECT_EQ(output_spec_text(output_spec_from_text(text)), text);
}

// Records written before the settings named their integrator and sampler read with the defaults the documents had
// then (there was one integrator, the path tracer).
TEST(StoredSettings, OlderTextWithFewerFieldsTakesTheDefaults) {
  const RenderSettings s = render_settings_from_text(
      R"({"estimator":"area","exposure_ev":0.0,"exr_precision":"float","height":64,"max_depth":8,"noise_target":0.0,)"
      R"("seed":3,"spp":16,"time_limit_s":0.0,"tonemap":"clamp","width":64})");
  EXPECT_EQ(s.integrator.name, "path");
  EXPECT_EQ(s.sampler, SamplerKind::kSobol);
  EXPECT_EQ(s.integrator.estimator, Estimator::kArea);
  EXPECT_FALSE(s.exr_half);
  EXPECT_EQ(s.width, 64);
}

TEST(StoredSettings, TextThatIsNoRecordsIsRefused) {
  for (const char* text : {"", "not json", "[]", R"({"width":0})", R"({"sampler":"halton"})"})
    EXPECT_THROW(render_settings_from_text(text), std::runtime_error) << text;
  for (const char* text : {"", "{}", "[]", R"(["gif"])"})
    EXPECT_THROW(output_spec_from_text(text), std::runtime_error) << text;
}

TEST(RenderSettingsMapping, TheStatusLeavesOutTheStoppingRulesThatAreOff) {
  const json off = render_settings_status_json(RenderSettings{});
  EXPECT_FALSE(off.contains("time_limit_s"));
  EXPECT_FALSE(off.contains("noise_target"));
  const json on = render_settings_status_json(read({{"time_limit_s", 30}, {"noise_target", 0.5}}));
  EXPECT_EQ(on["time_limit_s"], 30.0);
  EXPECT_EQ(on["noise_target"], 0.5);
}

}  // namespace
}  // namespace tessera
