// Wall-clock times as the API shows them: Unix milliseconds inside, RFC 3339 UTC outside.
#pragma once

#include <cstdint>
#include <string>

namespace tessera::server {

int64_t now_ms();
std::string rfc3339_ms(int64_t unix_ms);  // "2024-05-01T12:34:56.789Z"

}  // namespace tessera::server
