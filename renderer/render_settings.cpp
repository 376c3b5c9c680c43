#include "renderer/render_settings.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "renderer/aov.h"
#include "renderer/json_fields.h"
#include "renderer/scene_error.h"

namespace tessera {

using nlohmann::json;

namespace {

using fields::at;
using fields::boolean_key;
using fields::number_key;

// A value and the name documents give it: each table is read both ways, and its order is that of the error
// messages' lists.
template <typename T>
struct Named {
  T value;
  const char* name;
};

constexpr Named<SamplerKind> kSamplers[] = {{SamplerKind::kSobol, "sobol"}, {SamplerKind::kIndependent, "independent"}};
constexpr Named<Estimator> kEstimators[] = {
    {Estimator::kMis, "mis"}, {Estimator::kArea, "area"}, {Estimator::kHemisphere, "hemisphere"}};
constexpr Named<ToneMap> kTonemaps[] = {{ToneMap::kClamp, "clamp"}, {ToneMap::kAces, "aces"}};
constexpr Named<bool> kExrPrecisions[] = {{true, "half"}, {false, "float"}};  // RenderSettings::exr_half
constexpr Named<Denoiser> kDenoisers[] = {{Denoiser::kNone, "none"}, {Denoiser::kRegression, "regression"}};
constexpr Named<bool OutputSpec::*> kOutputFormats[] = {{&OutputSpec::png, "png"}, {&OutputSpec::exr, "exr"}};

template <typename T, size_t N>
const char* name_of(const Named<T> (&table)[N], T value) {
  for (const Named<T>& e : table)
    if (e.value == value) return e.name;
  return table[0].name;  // every value of the enumerations is in its table
}

// "\"a\", \"b\" or \"c\"" (with `last` "or").
std::string quoted_list(const std::vector<std::string>& names, const char* last) {
  std::string out;
  for (size_t i = 0; i < names.size(); ++i)
    out += (i == 0                  ? ""
            : i + 1 == names.size() ? std::string(" ") + last + " "
                                    : std::string(", ")) +
           ("\"" + names[i] + "\"");
  return out;
}

template <typename T, size_t N>
std::vector<std::string> names_of(const Named<T> (&table)[N]) {
  std::vector<std::string> out;
  for (const Named<T>& e : table) out.push_back(e.name);
  return out;
}

// obj[key], one of the table's names; `fallback` when absent.
template <typename T, size_t N>
T named_key(const json& obj, const std::string& key, const std::string& pointer, const Named<T> (&table)[N],
            T fallback) {
  auto it = obj.find(key);
  if (it == obj.end()) return fallback;
  if (it->is_string())
    for (const Named<T>& e : table)
      if (*it == e.name) return e.value;
  throw SceneError(at(pointer, key), "must be " + quoted_list(names_of(table), "or"));
}

}  // namespace

const char* sampler_name(SamplerKind sampler) {
  return name_of(kSamplers, sampler);
}
const char* estimator_name(Estimator estimator) {
  return name_of(kEstimators, estimator);
}
const char* tonemap_name(ToneMap tonemap) {
  return name_of(kTonemaps, tonemap);
}
const std::vector<std::string>& denoiser_features(Denoiser d) {
  static const std::vector<std::string> none, regression = {"albedo", "normal", "depth", "variance"};
  return d == Denoiser::kRegression ? regression : none;
}

const char* denoiser_name(Denoiser denoiser) {
  return name_of(kDenoisers, denoiser);
}

uint32_t default_min_spp(uint32_t spp) {
  // Sixteen samples before any pixel may stop: the error estimate is a sample standard deviation, whose own relative
  // error is about 1 / sqrt(2 (n - 1)), near 18 % at 16 samples, and a pixel whose few paths reach a light only now
  // and then must have drawn enough of them that all-dark first samples do not stop it. A fixed count rather than a
  // share of spp keeps what converges early (a flat sky) cheap whatever the budget: spp / 8 would give it 512
  // samples of a 4096-sample job.
  return std::min<uint32_t>(16, spp);
}

std::vector<std::string> film_aovs(const RenderSettings& settings) {
  const std::vector<std::string>& features = denoiser_features(settings.denoise);
  std::vector<std::string> aovs;
  for (const AovInfo& a : aov_table())
    if (std::find(settings.aovs.begin(), settings.aovs.end(), a.name) != settings.aovs.end() ||
        std::find(features.begin(), features.end(), a.name) != features.end())
      aovs.emplace_back(a.name);
  return aovs;
}

namespace {

// A document's "aovs": pass names aov.h knows, each once, that the integrator can make; held in the table's order.
std::vector<std::string> aovs_key(const json& render, const std::string& pointer, const std::string& integrator) {
  auto it = render.find("aovs");
  if (it == render.end()) return {};
  if (!it->is_array()) throw SceneError(at(pointer, "aovs"), "must be an array of pass names");
  const std::string list = at(pointer, "aovs");
  for (size_t i = 0; i < it->size(); ++i) {
    const json& name = (*it)[i];
    if (!name.is_string()) throw SceneError(at(list, i), "must be a pass name");
    const std::string text = name.get<std::string>();
    if (!find_aov(text)) throw SceneError(at(list, i), unknown_aov_message(text));
    for (size_t j = 0; j < i; ++j)
      if ((*it)[j] == name) throw SceneError(at(list, i), "the pass \"" + text + "\" is asked for twice");
    if (std::string problem = integrator_aov_problem(integrator, text); !problem.empty())
      throw SceneError(at(list, i), problem);
  }
  std::vector<std::string> aovs;
  for (const AovInfo& a : aov_table())
    if (std::find(it->begin(), it->end(), json(a.name)) != it->end()) aovs.emplace_back(a.name);
  return aovs;
}

// A document's "shutter" (frames.h): open and close in frames, open at most close, each within kMaxShutterFrames of
// the frame; steps, the motion's time steps, 2 to kMaxShutterSteps. `integer_of` reads an integer key as the other
// integers of "render" are read. None when absent.
template <typename IntegerOf>
std::optional<Shutter> shutter_key(const json& render, const std::string& pointer, const IntegerOf& integer_of) {
  auto it = render.find("shutter");
  if (it == render.end() || it->is_null()) return std::nullopt;
  const std::string sp = at(pointer, "shutter");
  if (!it->is_object()) throw SceneError(sp, "must be an object {\"open\", \"close\", \"steps\"}");
  Shutter shutter;
  for (const char* key : {"open", "close"}) {
    const auto v = it->find(key);
    if (v == it->end()) throw SceneError(at(sp, key), "is required: the shutter's opening and closing, in frames");
    const double d = fields::finite_number(*v, at(sp, key));
    if (std::abs(d) > kMaxShutterFrames)
      throw SceneError(at(sp, key), "must be within " + json(kMaxShutterFrames).dump() + " frames of the frame");
    (std::string(key) == "open" ? shutter.open : shutter.close) = d;
  }
  if (shutter.close < shutter.open)
    throw SceneError(at(sp, "close"), "must not be before open (" + json(shutter.open).dump() + ")");
  shutter.steps = static_cast<int>(integer_of(*it, sp, "steps", shutter.steps, 2, kMaxShutterSteps));
  return shutter;
}

}  // namespace

RenderSettings render_settings_from_json(const json& render, const std::string& pointer, const RenderLimits& limits) {
  RenderSettings s;
  if (render.is_null()) return s;
  if (!render.is_object()) throw SceneError(pointer, "must be an object");
  // An integer within [lo, hi], read exactly: a double holds every integer only up to 2^53 (2^53 + 1 read as one is
  // 2^53), so integers are compared as integers, and a number written with a fraction or exponent only where it is a
  // whole number a double holds exactly. obj[key] of the object at `where`; `fallback` when absent.
  auto integer_of = [](const json& obj, const std::string& where, const std::string& key, int64_t fallback, int64_t lo,
                       int64_t hi) -> int64_t {
    auto it = obj.find(key);
    if (it == obj.end()) return fallback;
    const std::string range = "must be between " + std::to_string(lo) + " and " + std::to_string(hi);
    if (it->is_number_unsigned() && it->get<uint64_t>() > static_cast<uint64_t>(hi))
      throw SceneError(at(where, key), range);
    if (it->is_number_integer()) {
      const int64_t v = it->get<int64_t>();
      if (v < lo || v > hi) throw SceneError(at(where, key), range);
      return v;
    }
    const double d = it->is_number_float() ? it->get<double>() : std::nan("");
    if (!std::isfinite(d) || d != std::floor(d)) throw SceneError(at(where, key), "must be an integer");
    if (d < static_cast<double>(lo) || d > static_cast<double>(hi) || std::abs(d) > 9007199254740992.0)
      throw SceneError(at(where, key), range);
    return static_cast<int64_t>(d);
  };
  auto integer = [&](const std::string& key, int64_t fallback, int64_t lo, int64_t hi) {
    return integer_of(render, pointer, key, fallback, lo, hi);
  };
  const RenderSettings defaults;
  s.width = static_cast<int>(integer("width", defaults.width, 1, limits.max_width));
  s.height = static_cast<int>(integer("height", defaults.height, 1, limits.max_height));
  s.spp = static_cast<uint32_t>(integer("spp", kDefaultSpp, 1, limits.max_spp));
  s.integrator.max_depth = static_cast<int>(integer("max_depth", defaults.integrator.max_depth, 0, limits.max_depth));
  s.integrator.max_volume_depth =
      static_cast<int>(integer("max_volume_depth", defaults.integrator.max_volume_depth, 0, limits.max_volume_depth));
  s.integrator.subsurface_guiding =
      boolean_key(render, "subsurface_guiding", pointer, defaults.integrator.subsurface_guiding);
  s.seed = static_cast<uint64_t>(integer("seed", 0, 0, (int64_t{1} << 53)));
  if (auto it = render.find("integrator"); it != render.end()) {
    const IntegratorRegistry& integrators = IntegratorRegistry::builtin();
    if (!it->is_string() || !integrators.has(it->get<std::string>()))
      throw SceneError(at(pointer, "integrator"), "must be " + quoted_list(integrators.names(), "or"));
    s.integrator.name = it->get<std::string>();
  }
  s.integrator.estimator = named_key(render, "estimator", pointer, kEstimators, defaults.integrator.estimator);
  s.sampler = named_key(render, "sampler", pointer, kSamplers, defaults.sampler);
  // Read as the other numbers of documents, as floats (fields::number_key): the settings hold what was read.
  s.time_limit_s = number_key(render, "time_limit_s", pointer, 0, 0, 7 * 24 * 3600.0);
  s.noise_target = number_key(render, "noise_target", pointer, 0, 0, 1);
  s.adaptive_threshold = number_key(render, "adaptive_threshold", pointer, 0, 0, 1);
  s.min_spp = static_cast<uint32_t>(integer("min_spp", default_min_spp(s.spp), 1, s.spp));
  if (s.adaptive_threshold > 0)
    if (std::string problem = integrator_adaptive_problem(s.integrator.name); !problem.empty())
      throw SceneError(at(pointer, "adaptive_threshold"), problem);
  s.display.exposure_ev = number_key(render, "exposure_ev", pointer, 0, -20, 20);
  s.display.tonemap = named_key(render, "tonemap", pointer, kTonemaps, defaults.display.tonemap);
  s.exr_half = named_key(render, "exr_precision", pointer, kExrPrecisions, defaults.exr_half);
  s.aovs = aovs_key(render, pointer, s.integrator.name);
  s.denoise = named_key(render, "denoise", pointer, kDenoisers, defaults.denoise);
  // The denoiser reads passes the integrator must make.
  for (const std::string& feature : denoiser_features(s.denoise))
    if (std::string problem = integrator_aov_problem(s.integrator.name, feature); !problem.empty())
      throw SceneError(at(pointer, "denoise"), "the denoiser \"" + std::string(denoiser_name(s.denoise)) +
                                                   "\" reads the pass \"" + feature + "\": " + problem);
  // A frame range (frames.h): frames start, start + step, ... end, at most limits.max_frames of them.
  if (auto it = render.find("frames"); it != render.end()) {
    const std::string fp = at(pointer, "frames");
    if (!it->is_object()) throw SceneError(fp, "must be an object {\"start\", \"end\", \"step\", \"chunk\"}");
    for (const char* key : {"start", "end"})
      if (!it->contains(key)) throw SceneError(at(fp, key), "is required: the range's first and last frame");
    FrameRange range;
    range.start = integer_of(*it, fp, "start", 0, -kMaxFrameNumber, kMaxFrameNumber);
    range.end = integer_of(*it, fp, "end", 0, -kMaxFrameNumber, kMaxFrameNumber);
    range.step = integer_of(*it, fp, "step", 1, 1, 2 * kMaxFrameNumber);
    range.chunk = integer_of(*it, fp, "chunk", 1, 1, 2 * kMaxFrameNumber + 1);
    if (range.end < range.start)
      throw SceneError(at(fp, "end"), "must not be before start (" + std::to_string(range.start) + ")");
    if (const uint64_t n = frame_count(range); n > limits.max_frames)
      throw SceneError(fp, "the range holds " + std::to_string(n) + " frames, more than the " +
                               std::to_string(limits.max_frames) + " a job may have");
    s.frames = range;
  }
  if (auto it = render.find("fps"); it != render.end()) {
    s.fps = fields::finite_number(*it, at(pointer, "fps"));
    if (!(s.fps > 0) || s.fps > 1000) throw SceneError(at(pointer, "fps"), "must be greater than 0 and at most 1000");
  }
  s.shutter = shutter_key(render, pointer, integer_of);
  return s;
}

json with_preview_defaults(const json& render) {
  if (!render.is_null() && !render.is_object()) return render;  // refused by render_settings_from_json, naming it
  json out = render.is_null() ? json::object() : render;
  const auto given = out.find("integrator");
  if (given != out.end() && !given->is_string()) return out;
  const std::string integrator = given == out.end() ? IntegratorSettings{}.name : given->get<std::string>();
  if (!out.contains("adaptive_threshold") && integrator_adaptive_problem(integrator).empty())
    out["adaptive_threshold"] = kPreviewAdaptiveThreshold;
  const auto& features = denoiser_features(Denoiser::kRegression);
  const bool feeds_denoiser = std::all_of(features.begin(), features.end(), [&](const std::string& feature) {
    return integrator_aov_problem(integrator, feature).empty();
  });
  if (!out.contains("denoise") && feeds_denoiser) out["denoise"] = denoiser_name(Denoiser::kRegression);
  return out;
}

json render_settings_to_json(const RenderSettings& s) {
  json out = {
      {"width", s.width},
      {"height", s.height},
      {"spp", s.spp},
      {"max_depth", s.integrator.max_depth},
      {"integrator", s.integrator.name},
      {"estimator", estimator_name(s.integrator.estimator)},
      {"seed", s.seed},
      {"sampler", sampler_name(s.sampler)},
      {"time_limit_s", s.time_limit_s},
      {"noise_target", s.noise_target},
      {"exposure_ev", s.display.exposure_ev},
      {"tonemap", tonemap_name(s.display.tonemap)},
      {"exr_precision", name_of(kExrPrecisions, s.exr_half)},
      {"max_volume_depth", s.integrator.max_volume_depth},
      {"subsurface_guiding", s.integrator.subsurface_guiding},
      {"aovs", s.aovs},
      {"denoise", denoiser_name(s.denoise)},
      {"frames", s.frames ? json{{"start", s.frames->start},
                                 {"end", s.frames->end},
                                 {"step", s.frames->step},
                                 {"chunk", s.frames->chunk}}
                          : json()},
      {"fps", s.fps},
      {"shutter",
       s.shutter ? json{{"open", s.shutter->open}, {"close", s.shutter->close}, {"steps", s.shutter->steps}} : json()},
      {"adaptive_threshold", s.adaptive_threshold},
      {"min_spp", s.min_spp}};
  // Keys the mapping gained after jobs were first stored are written only where they differ from their defaults:
  // records (and their checkpoints' fingerprints, FNV-1a of this text) of jobs stored before a key existed keep their
  // text byte for byte.
  static const json kLaterKeysDefaults = {{"max_volume_depth", IntegratorSettings{}.max_volume_depth},
                                          {"subsurface_guiding", IntegratorSettings{}.subsurface_guiding},
                                          {"aovs", json::array()},
                                          {"denoise", denoiser_name(Denoiser::kNone)},
                                          {"frames", nullptr},
                                          {"fps", kDefaultFps},
                                          {"shutter", nullptr},
                                          {"adaptive_threshold", 0.0}};
  for (const auto& [key, fallback] : kLaterKeysDefaults.items())
    if (out[key] == fallback) out.erase(key);
  if (s.min_spp == default_min_spp(s.spp)) out.erase("min_spp");
  return out;
}

json render_settings_status_json(const RenderSettings& s) {
  json out = render_settings_to_json(s);
  if (!(s.time_limit_s > 0)) out.erase("time_limit_s");
  if (!(s.noise_target > 0)) out.erase("noise_target");
  return out;
}

OutputSpec output_spec_from_json(const json& outputs, const std::string& pointer) {
  if (!outputs.is_array() || outputs.empty())
    throw SceneError(pointer, "must be a non-empty array of " + quoted_list(names_of(kOutputFormats), "and"));
  OutputSpec o;
  o.png = o.exr = false;
  for (size_t i = 0; i < outputs.size(); ++i) {
    const Named<bool OutputSpec::*>* format = nullptr;
    for (const auto& e : kOutputFormats)
      if (outputs[i] == e.name) format = &e;
    if (!format) throw SceneError(at(pointer, i), "must be " + quoted_list(names_of(kOutputFormats), "or"));
    o.*(format->value) = true;
  }
  return o;
}

json output_spec_to_json(const OutputSpec& o) {
  json out = json::array();
  for (const auto& e : kOutputFormats)
    if (o.*(e.value)) out.push_back(e.name);
  return out;
}

std::string render_settings_text(const RenderSettings& settings) {
  return render_settings_to_json(settings).dump();
}

RenderSettings render_settings_from_text(std::string_view text) {
  const json doc = json::parse(text, nullptr, false);
  if (!doc.is_object()) throw std::runtime_error("the stored render settings are not a JSON object");
  try {
    // Stored settings passed the limits of the server that took the job; they are read within the contract's (which
    // bounds the frame numbers, not how many frames a server takes).
    RenderLimits contract;
    contract.max_frames = UINT64_MAX;
    return render_settings_from_json(doc, "", contract);
  } catch (const SceneError& e) {
    throw std::runtime_error("the stored render settings are refused at " + e.pointer() + ": " + e.what());
  }
}

std::string output_spec_text(const OutputSpec& outputs) {
  return output_spec_to_json(outputs).dump();
}

OutputSpec output_spec_from_text(std::string_view text) {
  const json doc = json::parse(text, nullptr, false);
  try {
    return output_spec_from_json(doc, "");
  } catch (const SceneError& e) {
    throw std::runtime_error("the stored outputs are refused at " + e.pointer() + ": " + e.what());
  }
}

}  // namespace tessera
