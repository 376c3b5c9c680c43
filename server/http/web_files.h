// The web client (clients/web/), compiled into the daemon so it runs with no files beside it.
#pragma once

#include <optional>
#include <string>
#include <string_view>

namespace tessera::server {

// A file of clients/web/ by its relative path ("index.html"). Two more: "favicon.ico" is the page's SVG icon
// (favicon.svg), and "examples.json" the example jobs of proto/examples/, {"<file name>": <job document>, ...}.
std::optional<std::string_view> web_file(const std::string& path);
// The media type web_file(path) is served with.
std::string web_media_type(const std::string& path);

}  // namespace tessera::server
