#include "server/jobs/submission.h"

#include <algorithm>
#include <cctype>
#include <optional>
#include <vector>

#include "proto/contract.h"
#include "renderer/aov.h"
#include "renderer/job.h"
#include "renderer/scene.h"
#include "renderer/scene_error.h"

namespace tessera::server {

using nlohmann::json;

namespace {

// No key of a job document is longer than this; a longer one is refused as it is parsed, before the schema's error
// messages and pointers would copy it.
constexpr size_t kMaxKeyBytes = 256;

// Follows a parse as SAX events to say where it failed: the JSON pointer of the value being read (the value under
// the last key of an object, the next element of an array), or of the object holding a key that is too long.
class ErrorLocator final : public nlohmann::json_sax<json> {
 public:
  std::string pointer;
  bool key_too_long = false;

  bool null() override { return value(); }
  bool boolean(bool) override { return value(); }
  bool number_integer(number_integer_t) override { return value(); }
  bool number_unsigned(number_unsigned_t) override { return value(); }
  bool number_float(number_float_t, const string_t&) override { return value(); }
  bool string(string_t&) override { return value(); }
  bool binary(binary_t&) override { return value(); }
  bool start_object(std::size_t) override {
    levels_.push_back({false, 0, ""});
    return true;
  }
  bool key(string_t& k) override {
    if (k.size() > kMaxKeyBytes) {
      key_too_long = true;
      levels_.pop_back();
      locate();
      return false;
    }
    levels_.back().key = k;
    return true;
  }
  bool end_object() override {
    levels_.pop_back();
    return value();
  }
  bool start_array(std::size_t) override {
    levels_.push_back({true, 0, ""});
    return true;
  }
  bool end_array() override {
    levels_.pop_back();
    return value();
  }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override {
    if (!key_too_long) locate();
    return false;
  }

 private:
  struct Level {
    bool array;
    size_t index;
    std::string key;
  };
  bool value() {
    if (!levels_.empty() && levels_.back().array) ++levels_.back().index;
    return true;
  }
  void locate() {
    for (const Level& l : levels_) {
      pointer += '/';
      pointer += l.array ? std::to_string(l.index) : json_pointer_token(l.key);
    }
  }
  std::vector<Level> levels_;
};

struct KeyTooLong {};

// Refuses a job whose work, width x height x spp x what one sample may cost (renderer's sample_work), is above
// `max_work` (0: no limit).
std::optional<Problem> check_work(const RenderJob& job, double max_work) {
  const RenderSettings& s = job.settings;
  const bool scatters = job.scene && job.scene->has_scattering_media();
  std::string events;
  const double work = static_cast<double>(s.width) * s.height * s.spp * sample_work(s.integrator, scatters, &events);
  if (max_work <= 0 || work <= max_work) return std::nullopt;
  return Problem{422,
                 "width x height x spp x " + events + (scatters ? ", in a scene whose media scatter," : "") + " is " +
                     std::to_string(static_cast<long long>(work)) + ", above this server's limit of " +
                     std::to_string(static_cast<long long>(max_work)) + " (--max-work); lower the resolution, spp or " +
                     (scatters ? "max_depth or max_volume_depth" : "max_depth"),
                 "/render"};
}

// Refuses a job whose film (its beauty and passes' sums, renderer/aov.h film_bytes) is above `max_film_bytes` (0: no
// limit): a render holds it, and its checkpoint and outputs are of its size.
std::optional<Problem> check_film(const RenderSettings& s, uint64_t max_film_bytes) {
  const uint64_t bytes = film_bytes(s.width, s.height, film_aovs(s));
  if (max_film_bytes == 0 || bytes <= max_film_bytes) return std::nullopt;
  const uint64_t per_pixel = bytes / (static_cast<uint64_t>(s.width) * static_cast<uint64_t>(s.height));
  return Problem{
      422,
      "the film of this job takes " + std::to_string(bytes) + " bytes (width x height x " + std::to_string(per_pixel) +
          " a pixel for the beauty and its passes), above this server's limit of " + std::to_string(max_film_bytes) +
          " (--max-film-bytes); lower the resolution or ask for fewer passes",
      s.aovs.empty() ? "/render" : "/render/aovs"};
}

}  // namespace

std::variant<json, Problem> parse_document(std::string_view text, int max_depth) {
  if (proto::json_nesting_depth(text) > static_cast<size_t>(max_depth))
    return Problem{422, "the document is nested deeper than " + std::to_string(max_depth) + " levels", ""};
  std::string what;
  try {
    return json::parse(text, [](int, json::parse_event_t event, json& parsed) {
      if (event == json::parse_event_t::key && parsed.get_ref<const std::string&>().size() > kMaxKeyBytes)
        throw KeyTooLong{};
      return true;
    });
  } catch (const KeyTooLong&) {
  } catch (const json::exception& e) {  // parse_error, and out_of_range for a number that overflows a double
    what = e.what();
    if (const size_t at = what.find("] "); at != std::string::npos) what.erase(0, at + 2);  // "[json.exception...] "
  }
  ErrorLocator where;
  json::sax_parse(text, &where);
  if (where.key_too_long)
    return Problem{422, "an object has a key longer than " + std::to_string(kMaxKeyBytes) + " bytes", where.pointer};
  return Problem{400, "the document is not valid JSON: " + what, where.pointer};
}

std::string media_type(std::string_view content_type) {
  std::string_view t = content_type.substr(0, content_type.find(';'));
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.front()))) t.remove_prefix(1);
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.back()))) t.remove_suffix(1);
  std::string out(t);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return std::tolower(c); });
  return out;
}

std::variant<AcceptedJob, Problem> check_submission(std::string_view content_type, std::string_view body,
                                                    const SubmissionLimits& limits) {
  if (media_type(content_type) != "application/json")
    return Problem{415, "a job is submitted as application/json, not \"" + std::string(content_type) + "\"",
                   std::nullopt};
  if (body.find_first_not_of(" \t\r\n") == std::string_view::npos)
    return Problem{400, "the body is empty; expected a job document (JSON)", ""};
  auto document = parse_document(body, limits.max_depth);
  if (auto* problem = std::get_if<Problem>(&document)) return *problem;
  return check_job_document(std::move(std::get<json>(document)), limits);
}

std::variant<AcceptedJob, Problem> check_job_document(json document, const SubmissionLimits& limits) {
  AcceptedJob job;
  job.document = std::move(document);
  JobLoadOptions options;
  options.scene.build = false;  // names, indices and assets are checked; no BVH is built at submission
  options.scene.resolve_asset = limits.resolve_asset;
  options.scene.max_gltf_instances = limits.max_gltf_instances;
  options.scene.stop = limits.stop;
  options.limits = limits.render;

  const proto::SchemaSet& schemas = proto::contract_schemas();
  if (const auto errors = schemas.validate_all(job.document, "job.schema.json", limits.max_depth); !errors.empty()) {
    Problem problem{422, errors.front().message, errors.front().pointer};
    for (const proto::SchemaError& e : errors) problem.errors.emplace_back(e.pointer, e.message);
    // One answer with every error there is to tell: the renderer's checks run on what the schema errors leave (an
    // unknown material, say, next to a misspelt property); where they cannot, the answer says that they follow.
    const auto rest = schemas.valid_remainder(job.document, "job.schema.json", errors, limits.max_depth);
    if (rest && errors.size() < proto::kMaxReportedErrors) {
      try {
        load_job(*rest, options);
      } catch (const SceneError& e) {
        problem.errors.emplace_back(e.pointer(), e.what());
      } catch (const LoadStopped&) {
        return stopping_problem();
      }
    } else {
      problem.pending = std::string(proto::kChecksPending);
    }
    return problem;
  }

  RenderJob render_job;
  try {
    render_job = load_job(job.document, options);
  } catch (const SceneError& e) {
    return Problem{422, e.what(), e.pointer()};
  } catch (const LoadStopped&) {
    return stopping_problem();
  }
  if (auto problem = check_work(render_job, limits.max_work)) return *problem;
  if (auto problem = check_film(render_job.settings, limits.max_film_bytes)) return *problem;
  if (render_job.scene) job.warnings = render_job.scene->warnings;
  job.kind = job.document.value("kind", "scene");
  job.priority = job.document.value("priority", 0);
  job.settings = render_job.settings;
  job.outputs = render_job.outputs;
  return job;
}

}  // namespace tessera::server
