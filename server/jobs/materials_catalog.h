// The material models a job may use, read from the contract itself (material.schema.json): its allOf holds one
// if/then per model, `type` const -> a $defs entry. Served at GET /v1/materials, so clients build their editors from
// the same source the validator uses, and a new model appears there the day its schema entry is added.
#pragma once

#include <nlohmann/json.hpp>

#include "proto/json_schema.h"

namespace tessera::server {

// {"materials": [{"type", "title", "description", "parameters": [{"name", "description", "default", "minimum",
// "maximum", "schema"}]}]}; the parameter schemas have their $refs resolved. Models and parameters come in the order
// material.schema.json lists them (its allOf, each model's properties), the order a form shows them in.
nlohmann::json describe_materials(const proto::SchemaSet& schemas);

}  // namespace tessera::server
