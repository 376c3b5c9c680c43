// The head of an HTTP/1.1 request as it arrives (RFC 9112, section 2.1: a request line, field lines, an empty line),
// judged before cpp-httplib parses it. cpp-httplib 0.11 waits for CRLF CRLF (a head whose lines end with LF alone
// is never answered), drops a field line without a colon, takes "Name :" for a field other than "Name", reads a
// line that begins with whitespace as a field of its own and keeps control characters in values: a message that a
// proxy in front may read otherwise, the ground of request smuggling. Such a head is refused with 400 instead.
#pragma once

#include <cstddef>
#include <optional>
#include <string_view>
#include <utility>
#include <vector>

#include "server/base/problem.h"

namespace tessera::server {

// The parts of a well-formed head, as views into the bytes it was read from.
struct RequestHead {
  std::string_view method, target, version;
  std::vector<std::pair<std::string_view, std::string_view>> fields;  // name, value without its surrounding whitespace
};

struct HeadScan {
  size_t length = 0;               // through the empty line that ends the head; 0 while it has not all arrived
  size_t checked = 0;              // through the last whole line found well-formed: where the next scan may resume
  std::optional<Problem> problem;  // 400: a line of the head is malformed (known as soon as that line has arrived)
  RequestHead head;                // when the head is whole and well-formed
};

// Reads the head at the start of `bytes` (which may hold less than all of it, or more: the body, the next request).
// `from`, the `checked` of an earlier scan of the same head's first bytes, skips the lines that scan found
// well-formed: a head that arrives line by line is then read once, not once for every line that arrives; the head
// itself is read whole once its empty line has come.
HeadScan scan_head(std::string_view bytes, size_t from = 0);

// Whether the whole body of a request is among the `buffered` bytes that followed its head: it has no transfer
// coding (the end of a chunked body is known only by reading to it) and each Content-Length is a number of bytes
// within them; without either there is no body (RFC 9112, section 6.3).
bool body_arrived(const RequestHead& head, size_t buffered);

}  // namespace tessera::server
