// Judging a submitted job before it is stored: media type, JSON syntax, nesting depth, the contract's schema
// (proto/schemas/job.schema.json), then the renderer's own checks without building anything (material names that
// exist, indices in range, the configured size limits). Every refusal is a Problem naming the field.
#pragma once

#include <filesystem>
#include <functional>
#include <stop_token>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "renderer/scene_loader.h"
#include "server/base/problem.h"

namespace tessera::server {

struct SubmissionLimits {
  int max_depth = 64;  // nesting of arrays and objects
  RenderLimits render;
  double max_work = 0;          // width x height x spp x max_depth; 0: no limit
  uint64_t max_film_bytes = 0;  // a job's film with its passes (renderer/aov.h film_bytes); 0: no limit
  // Maps asset references (scene.gltf, scene.environment.map) to files; unset: none allowed.
  std::function<std::filesystem::path(const std::string& ref, const std::string& pointer)> resolve_asset;
  uint64_t max_gltf_instances = 1'000'000;  // SceneLoadOptions::max_gltf_instances
  std::stop_token stop;                     // the daemon stopping: the check ends with 503
};

struct AcceptedJob {
  nlohmann::json document;
  std::string kind;
  int priority = 0;
  RenderSettings settings;  // stored as render_settings_text, outputs as output_spec_text
  OutputSpec outputs;
  std::vector<std::string> warnings;  // from loading the scene (an optional glTF extension ignored, ...)
};

// A client's JSON text as a document: nothing nested deeper than `max_depth` (422), and text that does not parse, or
// a number beyond the range of a double (1e400), is a 400 naming the byte and the JSON pointer of the value at fault.
std::variant<nlohmann::json, Problem> parse_document(std::string_view text, int max_depth);

std::variant<AcceptedJob, Problem> check_submission(std::string_view content_type, std::string_view body,
                                                    const SubmissionLimits& limits);
// The same for a document already parsed (a multipart submission's job part).
std::variant<AcceptedJob, Problem> check_job_document(nlohmann::json document, const SubmissionLimits& limits);
// "application/json; charset=utf-8" -> "application/json".
std::string media_type(std::string_view content_type);

}  // namespace tessera::server
