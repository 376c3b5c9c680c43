// Job ids: 128 random bits as 32 lowercase hex digits. Opaque and unguessable, and checked against that exact
// pattern before an id from a request is used anywhere (the store, a file path).
#pragma once

#include <string>
#include <string_view>

namespace tessera::server {

std::string new_job_id();
bool is_valid_job_id(std::string_view id);

}  // namespace tessera::server
