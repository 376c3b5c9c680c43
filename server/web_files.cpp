#include "server/web_files.h"

#include <map>

namespace tessera::embedded {
const std::map<std::string, std::string_view>& web();
}  // namespace tessera::embedded

namespace tessera::server {

std::optional<std::string_view> web_file(const std::string& path) {
  auto it = embedded::web().find(path);
  if (it == embedded::web().end()) return std::nullopt;
  return it->second;
}

}  // namespace tessera::server
