// The API contract (proto/) and the web client (clients/web/), compiled into the binary so the daemon needs no
// files beside it and always serves the contract it validates with.
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "server/json_schema.h"

namespace tessera::server {

// Every proto/schemas/*.schema.json, by file name.
const SchemaSet& contract_schemas();
// proto/openapi.json, the source of truth of the HTTP API (proto/openapi.yaml is generated from it).
std::string_view openapi_json();
// A file of proto/ by its relative path ("schemas/job.schema.json").
std::optional<std::string_view> contract_file(const std::string& path);
// A file of clients/web/ by its relative path ("index.html").
std::optional<std::string_view> web_file(const std::string& path);

}  // namespace tessera::server
