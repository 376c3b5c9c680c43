// Fuzz target: a job document as the daemon judges a submission (server/jobs/submission.h check_submission): the JSON
// parser with its nesting limit and error locator, the contract's schema validator (proto/json_schema.h, every error
// collected), then tessera::load_job without building (scene jobs' objects, materials, lights, camera; material jobs'
// preview stage), and the Problem a refusal is answered with. The same text is judged as `tessera render` judges a
// job file (parse, validate_all, load_job). check_submission answers every document with an accepted job or a
// Problem; any exception, a crash or a sanitizer report is a finding. No asset resolves (references are refused).
#include <cstddef>
#include <cstdint>
#include <string_view>
#include <variant>

#include "server/jobs/submission.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tessera::server::SubmissionLimits limits;
  limits.render.max_width = 256;
  limits.render.max_height = 256;
  const auto judged = tessera::server::check_submission(
      "application/json", std::string_view(reinterpret_cast<const char*>(data), size), limits);
  if (const auto* problem = std::get_if<tessera::server::Problem>(&judged)) problem->to_json();
  return 0;
}
