// A JSON Schema (draft 2020-12) validator for the subset of keywords the contract in proto/schemas/ uses, so the
// daemon and the command line judge documents by the same files the daemon serves, with the same messages, and a
// standard validator (ajv) can judge them too.
//
// Supported: type, enum, const, required, properties, additionalProperties, propertyNames, items, minItems,
// maxItems, minimum, maximum, exclusiveMinimum, exclusiveMaximum, minLength, maxLength, pattern, allOf, anyOf,
// oneOf, if/then/else, $ref (local "#/..." and to sibling documents by file name, "material.schema.json#/$defs/x").
// Annotations ($id, $schema, $defs, title, description, default, format, examples) are ignored.
#pragma once

#include <cstddef>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace tessera::proto {

// An error of a document: where in the instance (RFC 6901 pointer) and what is wrong with it.
struct SchemaError {
  std::string pointer;
  std::string message;
  std::string keyword;  // the keyword that failed ("type", "required", ...)
};

// The most errors validate_all() reports of one document (a document of a thousand mistakes is answered with the
// first of them).
inline constexpr size_t kMaxReportedErrors = 20;

class SchemaSet {
 public:
  // Adds a schema document under its file name ("job.schema.json"); references between documents use that name.
  void add(const std::string& name, nlohmann::json schema);
  const nlohmann::json* document(const std::string& name) const;
  const std::map<std::string, nlohmann::json>& documents() const { return documents_; }

  // Validates `instance` against the document `name`. Returns the most specific error, or nothing when valid.
  // Instances nested deeper than `max_depth` are refused rather than walked (the walk is recursive).
  std::optional<SchemaError> validate(const nlohmann::json& instance, const std::string& name,
                                      int max_depth = 64) const;
  // Every error (up to `max_errors`), in document order: each member and item is checked whatever its siblings
  // hold, so a user sees all the mistakes of a document at once. The first is the one validate() returns.
  std::vector<SchemaError> validate_all(const nlohmann::json& instance, const std::string& name, int max_depth = 64,
                                        size_t max_errors = kMaxReportedErrors) const;

  // `instance` without the values `errors` (validate_all's) refused, when that is valid: what further checks (the
  // renderer's: material names, indices, assets) can judge while those errors stand, whatever their fixes will be.
  // A value is left out only where its absence cannot mean something else: an unknown property, or a scalar member
  // of an object (its default takes its place). Nothing when an error cannot be left out so (a missing property, a
  // wrong object or array, an item of an array) or the rest is still invalid: the further checks must wait.
  std::optional<nlohmann::json> valid_remainder(const nlohmann::json& instance, const std::string& name,
                                                const std::vector<SchemaError>& errors, int max_depth = 64) const;

  // Resolves a "$ref" found in document `base`. Returns nullptr when it names nothing; `*target_doc` receives the
  // name of the document the result lives in (for the references inside it).
  const nlohmann::json* resolve(const std::string& base, const std::string& ref, std::string* target_doc) const;

 private:
  std::map<std::string, nlohmann::json> documents_;
};

// Deepest nesting of arrays and objects in a JSON text, found without parsing it, so a hostile document
// ("[[[[...") is refused before any recursive code sees it. Malformed text is left for the parser to report.
size_t json_nesting_depth(std::string_view text);

}  // namespace tessera::proto
