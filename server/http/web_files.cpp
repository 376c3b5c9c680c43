#include "server/http/web_files.h"

#include <map>

namespace tessera::embedded {
const std::map<std::string, std::string_view>& web();
const std::map<std::string, std::string_view>& examples();
}  // namespace tessera::embedded

namespace tessera::server {

namespace {

// Browsers and other tools ask for /favicon.ico whatever a page links: it is the page's own icon, an SVG.
const std::string& file_name(const std::string& path) {
  static const std::string favicon = "favicon.svg";
  return path == "favicon.ico" ? favicon : path;
}

// The example jobs of proto/examples/ as one JSON object, {"cornell.json": {...}, ...} by file name: the web client
// lists them from it, so an example added there appears in the client with no copy of it kept beside the client.
std::string_view examples_json() {
  static const std::string text = [] {
    std::string out = "{";
    for (const auto& [name, document] : embedded::examples()) {
      // File names of proto/examples are plain ([A-Za-z0-9_.-]): nothing in them needs escaping.
      out += (out.size() > 1 ? ",\n\"" : "\n\"") + name + "\": ";
      out += document;
    }
    return out + "}\n";
  }();
  return text;
}

}  // namespace

std::optional<std::string_view> web_file(const std::string& path) {
  if (path == "examples.json") return examples_json();
  auto it = embedded::web().find(file_name(path));
  if (it == embedded::web().end()) return std::nullopt;
  return it->second;
}

std::string web_media_type(const std::string& path) {
  static const std::map<std::string, std::string> types = {{"js", "text/javascript; charset=utf-8"},
                                                           {"mjs", "text/javascript; charset=utf-8"},
                                                           {"css", "text/css; charset=utf-8"},
                                                           {"html", "text/html; charset=utf-8"},
                                                           {"svg", "image/svg+xml"},
                                                           {"png", "image/png"},
                                                           {"ico", "image/x-icon"},
                                                           {"json", "application/json"},
                                                           {"map", "application/json"},
                                                           {"webmanifest", "application/manifest+json"}};
  const std::string& name = file_name(path);
  auto it = types.find(name.substr(name.rfind('.') + 1));
  return it == types.end() ? "application/octet-stream" : it->second;
}

}  // namespace tessera::server
