// Judging a submitted job before it is stored: media type, JSON syntax, nesting depth, the contract's schema
// (proto/schemas/job.schema.json), then the renderer's own checks without building anything (material names that
// exist, indices in range, the configured size limits). Every refusal is a Problem naming the field.
#pragma once

#include <string>
#include <string_view>
#include <variant>

#include <nlohmann/json.hpp>

#include "renderer/scene_loader.h"
#include "server/problem.h"

namespace tessera::server {

struct SubmissionLimits {
  int max_depth = 64;  // nesting of arrays and objects
  RenderLimits render;
};

struct AcceptedJob {
  nlohmann::json document;
  std::string kind;
  int priority = 0;
  nlohmann::json settings;  // the render settings, defaults filled in
  nlohmann::json outputs;   // ["png", "exr"]
  uint32_t spp = 0;
};

std::variant<AcceptedJob, Problem> check_submission(std::string_view content_type, std::string_view body,
                                                    const SubmissionLimits& limits);

// The render settings as the job status shows them.
nlohmann::json render_settings_json(const RenderSettings& s);

}  // namespace tessera::server
