// The API contract (proto/: the JSON Schemas and the OpenAPI document), compiled into every program that links
// tessera_contract: the daemon validates with, and serves, exactly these files, and the command line checks a
// document against the same schemas before it renders it.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "proto/json_schema.h"

namespace tessera::proto {

// Every proto/schemas/*.schema.json, by file name.
const SchemaSet& contract_schemas();
// proto/openapi.json, the source of truth of the HTTP API (proto/openapi.yaml is generated from it).
std::string_view openapi_json();
// A file of proto/ by its relative path ("schemas/job.schema.json").
std::optional<std::string_view> contract_file(const std::string& path);

// Where a job document names an asset (scene.schema.json's asset_ref, an asset id on the daemon). A multipart
// submission may write the name of a file sent with it there (the daemon stores the file and writes its id in its
// place), and a job rendered by `tessera render` the name of a file beside it (read from there).
// A "*" token stands for every index of an array (asset_refs expands it).
inline constexpr std::string_view kAssetRefPointers[] = {"/scene/gltf", "/scene/environment/map", "/scene/medium/grid",
                                                         "/scene/objects/*/medium/grid"};
// The pointers of `doc` where kAssetRefPointers' patterns find a string, in the patterns' order.
std::vector<std::string> asset_refs(const nlohmann::json& doc);

// Said with a document's schema errors when the checks that follow the schema's (the renderer's: material names,
// indices, assets, limits) could not run on what the errors leave (SchemaSet::valid_remainder): the problem's
// "pending", and a line of `tessera render`.
inline constexpr std::string_view kChecksPending =
    "more checks (material names, indices, assets, limits) follow once these errors are fixed";

}  // namespace tessera::proto
