// Errors as the API answers them: RFC 9457 problem details (application/problem+json), with the JSON pointer of
// the offending field when a document is at fault. proto/schemas/problem.schema.json describes the shape.
#pragma once

#include <optional>
#include <string>

#include <nlohmann/json.hpp>

namespace tessera::server {

struct Problem {
  int status = 500;
  std::string detail;
  std::optional<std::string> pointer;

  // "https://tessera.dev/problems/<slug>" and a title, both chosen by the status.
  std::string type() const;
  std::string title() const;
  nlohmann::json to_json() const;
};

inline constexpr const char* kProblemMediaType = "application/problem+json";

}  // namespace tessera::server
