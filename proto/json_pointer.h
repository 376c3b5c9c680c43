// JSON Pointer (RFC 6901) reference tokens, for the pointers every error message names.
#pragma once

#include <string>

namespace tessera::proto {

// RFC 6901 §3 escaping of one reference token: '~' becomes "~0" and '/' becomes "~1".
inline std::string json_pointer_token(const std::string& key) {
  std::string out;
  for (char c : key) {
    if (c == '~')
      out += "~0";
    else if (c == '/')
      out += "~1";
    else
      out += c;
  }
  return out;
}

}  // namespace tessera::proto
