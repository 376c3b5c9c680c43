// Errors as the API answers them: RFC 9457 problem details (application/problem+json), with the JSON pointer of
// the offending field when a document is at fault. proto/schemas/problem.schema.json describes the shape.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace tessera::server {

struct Problem {
  int status = 500;
  std::string detail;
  std::optional<std::string> pointer;
  std::optional<int> retry_after_s = std::nullopt;  // when to ask again (429, 503): a Retry-After header
  // Every error of a refused document, as (pointer, detail), when it has more than one: the first is `detail` and
  // `pointer`; the answer lists them all in "errors".
  std::vector<std::pair<std::string, std::string>> errors = {};
  // With a document's errors: the checks that could not run because of them, and follow once they are fixed.
  std::optional<std::string> pending = std::nullopt;

  // "https://tessera.dev/problems/<slug>" and a title, both chosen by the status.
  std::string type() const;
  std::string title() const;
  nlohmann::json to_json() const;
};

inline constexpr const char* kProblemMediaType = "application/problem+json";

// 507: the data directory has no room for what a request would have stored (`why` says how that was found out:
// below --min-free-disk before writing, or a write that ran out of space) and `kept` what of the request was stored
// all the same.
Problem insufficient_storage(const std::string& why, const std::string& kept = "nothing was stored");

// 503: the daemon is stopping, and gave up checking what the request sent (a scene or an asset being loaded);
// nothing was stored. Retry-After: 5 (another instance, or this one restarted).
Problem stopping_problem();

}  // namespace tessera::server
