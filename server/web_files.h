// The web client (clients/web/), compiled into the daemon so it runs with no files beside it.
#pragma once

#include <optional>
#include <string>
#include <string_view>

namespace tessera::server {

// A file of clients/web/ by its relative path ("index.html").
std::optional<std::string_view> web_file(const std::string& path);

}  // namespace tessera::server
