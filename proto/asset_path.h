// Files of an asset named from inside it: a glTF buffer's or image's URI, a JSON scene's texture or glTF file, the
// name of a file in an upload. One rule for the daemon, the renderer and the command line: a relative path inside
// the asset's own folder or upload, subfolders allowed, nothing outside it. Header-only, so that every program can
// use it without linking anything.
//
// A glTF URI is a relative reference of RFC 3986 (glTF 2.0, section 3.3 "URIs": "reserved characters must be
// percent-encoded", so a space is %20): percent-decoded first (RFC 3986, 2.1), then judged as a path. "./" segments
// are dropped; "..", absolute paths, a scheme or a drive (any ':'), backslashes, control characters and names
// starting with a dot (hidden files, the daemon's own metadata) are refused, decoded or not.
#pragma once

#include <cctype>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace tessera::proto {

struct AssetPath {
  std::string path;     // normalised: segments joined by '/', no "." segments; empty when refused
  std::string problem;  // why the reference is refused; empty when accepted
};

// A data: URI carries its bytes and names no file (the scheme is case-insensitive: RFC 3986, 3.1).
inline bool is_data_uri(std::string_view uri) {
  if (uri.size() < 5) return false;
  for (size_t i = 0; i < 4; ++i)
    if (std::tolower(static_cast<unsigned char>(uri[i])) != "data"[i]) return false;
  return uri[4] == ':';
}

// The file a relative path names inside an asset, normalised; or why it may not name one.
inline AssetPath asset_path(std::string_view path) {
  constexpr size_t kMaxBytes = 1024, kMaxSegmentBytes = 255, kMaxDepth = 16;
  auto refused = [](std::string why) { return AssetPath{"", std::move(why)}; };
  if (path.empty()) return refused("an empty path");
  if (path.size() > kMaxBytes) return refused("longer than " + std::to_string(kMaxBytes) + " bytes");
  for (char c : path) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f) return refused("control characters are not allowed");
    if (c == '\\') return refused("backslashes are not allowed (folders are separated by /)");
    if (c == ':')
      return refused("a scheme or a drive (\":\") is not allowed: only files of the same asset, or data: URIs");
  }
  if (path[0] == '/') return refused("absolute paths are not allowed");
  AssetPath out;
  size_t depth = 0;
  for (size_t at = 0; at <= path.size();) {
    size_t end = path.find('/', at);
    if (end == std::string_view::npos) end = path.size();
    const std::string_view segment = path.substr(at, end - at);
    at = end + 1;
    if (segment.empty() || segment == ".") continue;
    if (segment == "..") return refused("\"..\" is not allowed");
    if (segment[0] == '.') return refused("names starting with a dot are not allowed");
    if (segment.size() > kMaxSegmentBytes)
      return refused("a name is longer than " + std::to_string(kMaxSegmentBytes) + " bytes");
    if (++depth > kMaxDepth) return refused("more than " + std::to_string(kMaxDepth) + " folders deep");
    if (!out.path.empty()) out.path += '/';
    out.path += segment;
  }
  if (out.path.empty()) return refused("names a folder, not a file");
  if (path.back() == '/') return refused("names a folder, not a file");
  return out;
}

// The file a glTF URI names inside its asset: percent-decoded, then as asset_path(). A query or fragment ('?', '#'
// not encoded) names no file.
inline AssetPath asset_path_from_uri(std::string_view uri) {
  auto refused = [](std::string why) { return AssetPath{"", std::move(why)}; };
  if (is_data_uri(uri)) return refused("a data: URI names no file");
  auto hex = [](char c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
  };
  std::string decoded;
  for (size_t i = 0; i < uri.size(); ++i) {
    const char c = uri[i];
    if (c == '?' || c == '#') return refused("a query or fragment is not allowed (encode '?' and '#' in file names)");
    if (c != '%') {
      decoded += c;
      continue;
    }
    if (i + 2 >= uri.size() || hex(uri[i + 1]) < 0 || hex(uri[i + 2]) < 0)
      return refused("a malformed percent-encoding (% must be followed by two hexadecimal digits)");
    decoded += static_cast<char>(hex(uri[i + 1]) * 16 + hex(uri[i + 2]));
    i += 2;
  }
  return asset_path(decoded);
}

// `path` as a URI: unreserved characters (RFC 3986, 2.3) and '/' as they are, every other byte percent-encoded.
inline std::string uri_from_asset_path(std::string_view path) {
  static const char* digits = "0123456789ABCDEF";
  std::string out;
  for (char c : path) {
    const auto u = static_cast<unsigned char>(c);
    if (std::isalnum(u) || c == '-' || c == '.' || c == '_' || c == '~' || c == '/') {
      out += c;
    } else {
      out += '%';
      out += digits[u >> 4];
      out += digits[u & 15];
    }
  }
  return out;
}

// The regular file that `path` (accepted by asset_path()) names inside the folder `root`, with every symbolic link
// resolved; nullopt when there is none, or when it resolves outside `root` (a link that leads out: then `*outside`
// is set).
inline std::optional<std::filesystem::path> confined_file(const std::filesystem::path& root, const std::string& path,
                                                          bool* outside = nullptr) {
  namespace fs = std::filesystem;
  if (outside) *outside = false;
  std::error_code ec;
  const fs::path base = fs::canonical(root, ec);
  if (ec) return std::nullopt;
  const fs::path full = fs::canonical(base / fs::path(path), ec);
  if (ec) return std::nullopt;
  auto b = base.begin();
  auto f = full.begin();
  for (; b != base.end(); ++b, ++f) {
    if (f == full.end() || *b != *f) {
      if (outside) *outside = true;
      return std::nullopt;
    }
  }
  if (!fs::is_regular_file(full, ec)) return std::nullopt;
  return full;
}

}  // namespace tessera::proto
