#include "server/http/request_head.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cstdint>
#include <string>

namespace tessera::server {

namespace {

Problem bad_head(std::string detail) {
  return Problem{400, std::move(detail), std::nullopt};
}

// tchar (RFC 9110, section 5.6.2): what a method or a field name is made of.
bool is_tchar(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) ||
         std::string_view("!#$%&'*+-.^_`|~").find(c) != std::string_view::npos;
}

bool is_token(std::string_view s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), is_tchar);
}

// A control character: NUL to US, and DEL.
bool is_ctl(char c) {
  const auto u = static_cast<unsigned char>(c);
  return u < 0x20 || u == 0x7f;
}

bool is_space_or_tab(char c) {
  return c == ' ' || c == '\t';
}

// HTTP-version = "HTTP/" DIGIT "." DIGIT (RFC 9112, section 2.3).
bool is_http_version(std::string_view v) {
  return v.size() == 8 && v.substr(0, 5) == "HTTP/" && std::isdigit(static_cast<unsigned char>(v[5])) && v[6] == '.' &&
         std::isdigit(static_cast<unsigned char>(v[7]));
}

// request-line = method SP request-target SP HTTP-version (RFC 9112, section 3), one space between each.
std::optional<Problem> parse_request_line(std::string_view line, RequestHead& head) {
  const size_t sp1 = line.find(' ');
  const size_t sp2 = sp1 == std::string_view::npos ? sp1 : line.find(' ', sp1 + 1);
  if (sp2 != std::string_view::npos && line.find(' ', sp2 + 1) == std::string_view::npos) {
    head.method = line.substr(0, sp1);
    head.target = line.substr(sp1 + 1, sp2 - sp1 - 1);
    head.version = line.substr(sp2 + 1);
    if (is_token(head.method) && !head.target.empty() && std::none_of(head.target.begin(), head.target.end(), is_ctl) &&
        is_http_version(head.version))
      return std::nullopt;
  }
  return bad_head(
      "the request line must be a method, a target and an HTTP version (HTTP/1.1), one space between each (RFC 9112, "
      "section 3)");
}

// field-line = field-name ":" OWS field-value OWS (RFC 9112, section 5).
std::optional<Problem> parse_field_line(std::string_view line, RequestHead& head) {
  // obs-fold: a line that continues the one before; a server may reject the message with 400 (RFC 9112, 5.2).
  if (is_space_or_tab(line.front()))
    return bad_head(
        "a header line begins with whitespace: folded header lines (obs-fold) are not accepted (RFC 9112, "
        "section 5.2)");
  const size_t colon = line.find(':');
  if (colon == std::string_view::npos) return bad_head("a header line has no colon (RFC 9112, section 5)");
  const std::string_view name = line.substr(0, colon);
  // A server must reject whitespace between a field name and its colon with 400 (RFC 9112, section 5.1).
  if (!name.empty() && is_space_or_tab(name.back()))
    return bad_head("a header field name is followed by whitespace before its colon (RFC 9112, section 5.1)");
  if (!is_token(name)) return bad_head("a header field name must be a token (RFC 9110, section 5.1)");
  std::string_view value = line.substr(colon + 1);
  while (!value.empty() && is_space_or_tab(value.front())) value.remove_prefix(1);
  while (!value.empty() && is_space_or_tab(value.back())) value.remove_suffix(1);
  // A field value is visible characters, spaces and tabs; NUL, CR and LF in one are dangerous (RFC 9110, 5.5).
  if (std::any_of(value.begin(), value.end(), [](char c) { return is_ctl(c) && c != '\t'; }))
    return bad_head("the value of the header " + std::string(name.substr(0, 64)) +
                    " has a control character (RFC 9110, section 5.5)");
  head.fields.emplace_back(name, value);
  return std::nullopt;
}

bool same_letters(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) == std::tolower(static_cast<unsigned char>(y));
         });
}

}  // namespace

HeadScan scan_head(std::string_view bytes, size_t from) {
  HeadScan scan;
  scan.checked = from;
  for (size_t start = from, lf; (lf = bytes.find('\n', start)) != std::string_view::npos; start = lf + 1) {
    // RFC 9112, section 2.2 lets a server take a bare LF for the end of a line. This one does not: a proxy in front
    // that does not would read other lines than this server (a header hidden in another's value).
    if (lf == start || bytes[lf - 1] != '\r') {
      scan.problem = bad_head("the request's lines must end with CRLF, not LF alone (RFC 9112, section 2.2)");
      return scan;
    }
    const std::string_view line = bytes.substr(start, lf - 1 - start);
    if (start > 0 && line.empty()) {
      if (from > 0) return scan_head(bytes);  // whole: read from its first line, for the fields skipped above
      scan.length = lf + 1;
      scan.checked = scan.length;
      return scan;
    }
    scan.problem = start == 0 ? parse_request_line(line, scan.head) : parse_field_line(line, scan.head);
    if (scan.problem) return scan;
    scan.checked = lf + 1;
  }
  return scan;
}

bool body_arrived(const RequestHead& head, size_t buffered) {
  for (const auto& [name, value] : head.fields) {
    if (same_letters(name, "Transfer-Encoding")) return false;
    if (!same_letters(name, "Content-Length")) continue;
    uint64_t length = 0;
    const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), length);
    if (ec != std::errc() || end != value.data() + value.size() || length > buffered) return false;
  }
  return true;
}

}  // namespace tessera::server
