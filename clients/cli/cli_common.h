// What the two programs of the command-line tool share: `tessera`, the client of a daemon (submit, watch, fetch,
// list, cancel), and `tessera-render`, the local renderer it runs for `tessera render` and `tessera merge`.
//
// Exit codes (render farm managers tell "try again" from "this can never work"): 0 done, 1 fatal (bad input, a
// refused job, a failed render), 2 usage, 75 retry (transient: I/O, network, server 5xx, 429, 503).
#pragma once

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <new>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "proto/did_you_mean.h"

namespace tessera::cli {

constexpr int kExitOk = 0;
constexpr int kExitFatal = 1;  // bad input: the same command will fail again
constexpr int kExitUsage = 2;
constexpr int kExitRetry = 75;  // EX_TEMPFAIL: a transient failure (I/O, resources, network, server overload)

// A failure with the exit code it deserves; caught by run_command().
struct Failure : std::runtime_error {
  int code;
  Failure(int c, const std::string& what) : std::runtime_error(what), code(c) {}
};
[[noreturn]] inline void fatal(const std::string& what) {
  throw Failure(kExitFatal, what);
}
[[noreturn]] inline void retry(const std::string& what) {
  throw Failure(kExitRetry, what);
}

// A usage error for an option the command does not know, with the closest one it does.
[[noreturn]] inline void unknown_option(const std::string& option, std::initializer_list<std::string_view> known) {
  throw std::invalid_argument("unknown option " + option + proto::did_you_mean(option, known));
}

// What a file that is not a JSON document is, by its first bytes (its magic number): an image given where a job
// belongs ("a PNG image"), or "" when it is none of those the tool knows.
inline std::string sniff_file_kind(std::string_view bytes) {
  struct Magic {
    std::string_view start;
    const char* kind;
  };
  static constexpr Magic kMagics[] = {
      {"\x89PNG\r\n\x1a\n", "a PNG image"},
      {"\xff\xd8\xff", "a JPEG image"},
      {"\x76\x2f\x31\x01", "an OpenEXR image"},
      {"#?RADIANCE", "a Radiance HDR image"},
      {"#?RGBE", "a Radiance HDR image"},
      {"glTF", "a binary glTF scene (.glb) under another name"},
      {"TSRFILM\n", "a tessera partial film (.tfilm)"},
  };
  for (const Magic& m : kMagics)
    if (bytes.substr(0, m.start.size()) == m.start) return m.kind;
  return "";
}

// A JSON document read from `name`: a file of another kind (an image) is fatal saying what it is and what a job is;
// malformed text is fatal, with the line and column where it broke.
inline nlohmann::json parse_json(const std::string& text, const std::string& name) {
  if (const std::string kind = sniff_file_kind(text); !kind.empty())
    fatal(name + " is " + kind + ", not a job: a job is a JSON document (.json), or a glTF scene (.glb or .gltf)");
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {  // parse_error; out_of_range for a number beyond a double
    std::string what = e.what();
    if (const size_t at = what.find("] "); what.rfind("[json.exception", 0) == 0 && at != std::string::npos)
      what.erase(0, at + 2);
    fatal(name + " is not valid JSON: " + what);
  }
}

inline long long parse_integer(const std::string& option, const std::string& v) {
  size_t pos = 0;
  long long n = 0;
  try {
    n = std::stoll(v, &pos);
  } catch (const std::exception&) {
    pos = 0;
  }
  if (pos != v.size() || v.empty()) throw std::invalid_argument(option + " needs an integer, not \"" + v + "\"");
  return n;
}

inline double parse_number(const std::string& option, const std::string& v) {
  size_t pos = 0;
  double d = 0;
  try {
    d = std::stod(v, &pos);
  } catch (const std::exception&) {
    pos = 0;
  }
  if (pos != v.size() || v.empty() || !std::isfinite(d))
    throw std::invalid_argument(option + " needs a number, not \"" + v + "\"");
  return d;
}

// --animation's value as scene.animation: an index when it is all digits (and a plausible index), else a name.
inline nlohmann::json animation_choice(const std::string& v) {
  if (!v.empty() && v.size() <= 7 && std::all_of(v.begin(), v.end(), [](char c) { return c >= '0' && c <= '9'; }))
    return std::stoll(v);
  return v;
}

inline std::vector<long long> parse_list(const std::string& option, const std::string& v, char sep, size_t count) {
  std::vector<long long> out;
  std::stringstream ss(v);
  std::string item;
  while (std::getline(ss, item, sep)) out.push_back(parse_integer(option, item));
  if (out.size() != count)
    throw std::invalid_argument(option + " needs " + std::to_string(count) + " integers separated by '" +
                                std::string(1, sep) + "', not \"" + v + "\"");
  return out;
}

inline std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

inline std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fatal("cannot open " + path.string() + ": " + std::strerror(errno));
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Writes through a temporary file renamed into place: a reader never sees half a file.
inline void write_file_atomic(const std::string& path, std::string_view bytes) {
  const std::string tmp = path + ".part";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) retry("cannot write " + tmp + ": " + std::strerror(errno));
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out) retry("cannot write " + tmp + ": " + std::strerror(errno));
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) retry("cannot rename " + tmp + " to " + path + ": " + ec.message());
}

// Refuses an output that cannot be written, before the work that would fill it (a render of an hour must not end
// in "cannot write"): a missing directory, a directory in the file's place, or a file or directory without write
// permission is bad input (1), where a write that fails later (a full disk) is transient (75). The directory must be
// writable even when the file exists: results are written beside it and renamed into place.
inline void check_writable(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path file(path);
  if (fs::is_directory(file, ec)) fatal("cannot write " + path + ": it is a directory");
  const fs::path dir = file.parent_path().empty() ? fs::path(".") : file.parent_path();
  if (!fs::exists(dir, ec)) fatal("cannot write " + path + ": there is no directory " + dir.string());
  if (!fs::is_directory(dir, ec)) fatal("cannot write " + path + ": " + dir.string() + " is not a directory");
  if (::access(dir.c_str(), W_OK | X_OK) != 0)
    fatal("cannot write " + path + ": directory " + dir.string() + ": " + std::strerror(errno));
  if (fs::exists(file, ec) && ::access(file.c_str(), W_OK) != 0)
    fatal("cannot write " + path + ": " + std::strerror(errno));
}

// A program's main(): runs `command` and turns what it throws into a message on stderr and an exit code.
template <typename Command>
int run_command(Command&& command) {
  try {
    return command();
  } catch (const Failure& f) {
    if (f.what()[0]) std::fprintf(stderr, "tessera: %s\n", f.what());
    return f.code;
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "tessera: %s\n", e.what());
    return kExitUsage;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "tessera: out of memory\n");
    return kExitRetry;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tessera: %s\n", e.what());
    return kExitRetry;
  }
}

}  // namespace tessera::cli
