// Fuzz target: the head of an HTTP/1.1 request as tesserad's transport judges it before cpp-httplib parses it
// (server/http/request_head.h scan_head, then body_arrived on what follows it). Besides crashes and sanitizer reports,
// what the scan promises is checked: a refusal is a 400; a whole head ends within the bytes, its parts are views into
// them, the bytes up to its end scan as the same head and any shorter prefix as one that has not all arrived.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "server/http/request_head.h"

namespace {

bool inside(std::string_view part, std::string_view bytes) {
  return part.empty() || (part.data() >= bytes.data() && part.data() + part.size() <= bytes.data() + bytes.size());
}

bool parts_inside(const tessera::server::RequestHead& head, std::string_view bytes) {
  bool ok = inside(head.method, bytes) && inside(head.target, bytes) && inside(head.version, bytes);
  for (const auto& [name, value] : head.fields) ok = ok && inside(name, bytes) && inside(value, bytes);
  return ok;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera::server;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  const HeadScan scan = scan_head(bytes);
  if (scan.problem) {
    if (scan.problem->status != 400) std::abort();
    return 0;
  }
  if (scan.length == 0) return 0;
  const std::string_view head = bytes.substr(0, scan.length);
  if (scan.length > size || !parts_inside(scan.head, head)) std::abort();
  if (scan_head(head).length != scan.length || scan_head(head.substr(0, scan.length - 1)).length != 0) std::abort();
  body_arrived(scan.head, size - scan.length);
  return 0;
}
