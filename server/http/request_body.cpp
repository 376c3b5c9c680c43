#include "server/http/request_body.h"

#include <algorithm>
#include <charconv>
#include <string>

#include "server/http/http_transport.h"

namespace tessera::server {

namespace {

// Every value of a header, whether it came as several fields or as one comma-separated list (RFC 9110, 5.3).
std::vector<std::string> field_values(const httplib::Request& req, const char* name) {
  std::vector<std::string> out;
  auto [begin, end] = req.headers.equal_range(name);
  for (auto it = begin; it != end; ++it) {
    const std::string& line = it->second;
    size_t at = 0;
    while (at <= line.size()) {
      size_t comma = line.find(',', at);
      if (comma == std::string::npos) comma = line.size();
      std::string v = line.substr(at, comma - at);
      v.erase(0, v.find_first_not_of(" \t"));
      v.erase(v.find_last_not_of(" \t") + 1);
      out.push_back(v);
      at = comma + 1;
    }
  }
  return out;
}

bool same_letters(const std::string& a, const char* b) {
  const std::string_view bv(b);
  return a.size() == bv.size() && std::equal(a.begin(), a.end(), bv.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) == y;
         });
}

Problem bad(int status, std::string detail) {
  return Problem{status, std::move(detail), std::nullopt};
}

}  // namespace

bool has_body(const httplib::Request& req) {
  if (req.has_header("Transfer-Encoding")) return true;
  const std::string length = req.get_header_value("Content-Length");
  return !length.empty() && length.find_first_not_of('0') != std::string::npos;
}

std::optional<Problem> check_method(std::string_view method) {
  static const char* const kMethods[] = {"GET", "HEAD", "POST", "PATCH", "DELETE", "PUT", "OPTIONS"};
  if (std::any_of(std::begin(kMethods), std::end(kMethods), [&](const char* m) { return method == m; }))
    return std::nullopt;
  // A method the server does not recognise or implement is answered 501 (RFC 9110, sections 9.1 and 15.6.2).
  return bad(501, "the method " + std::string(method.substr(0, 16)) + " is not implemented by this server");
}

std::optional<Problem> check_request_head(const httplib::Request& req, size_t max_body_bytes) {
  if (auto problem = check_method(req.method)) return problem;

  // A client must send Host in every HTTP/1.1 request, and a server must answer 400 to a request without one or with
  // more than one (RFC 9112, 3.2).
  if (req.version == "HTTP/1.1" && req.get_header_value_count("Host") != 1)
    return bad(400, req.has_header("Host") ? "the request has more than one Host header"
                                           : "an HTTP/1.1 request needs a Host header (RFC 9112, section 3.2)");

  const std::vector<std::string> lengths = field_values(req, "Content-Length");
  const std::vector<std::string> codings = field_values(req, "Transfer-Encoding");
  if (!codings.empty()) {
    // A message with both is a way to smuggle requests past proxies that read one and not the other; the server
    // must close the connection after answering (RFC 9112, 6.1).
    if (!lengths.empty()) return bad(400, "a request may not have both Transfer-Encoding and Content-Length");
    if (req.version != "HTTP/1.1") return bad(400, "Transfer-Encoding needs HTTP/1.1");
    if (codings.size() != 1 || !same_letters(codings[0], "chunked"))
      return bad(501, "the only transfer coding this server reads is chunked");
  }
  if (!lengths.empty()) {
    // Several Content-Length values that differ make the message's length unknowable (RFC 9112, 6.3).
    if (std::any_of(lengths.begin(), lengths.end(), [&](const std::string& v) { return v != lengths[0]; }))
      return bad(400, "the request has Content-Length values that differ");
    const std::string& text = lengths[0];
    uint64_t length = 0;
    auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), length);
    if (text.empty() || text[0] == '+' || (ec != std::errc() && ec != std::errc::result_out_of_range) ||
        end != text.data() + text.size())
      return bad(400, "Content-Length must be a number of bytes, not \"" + text.substr(0, 32) + "\"");
    if (ec == std::errc::result_out_of_range || length > max_body_bytes)
      return bad(413, "the request body of " + text.substr(0, 32) + " bytes exceeds the limit of " +
                          std::to_string(max_body_bytes) + " bytes (--max-body-bytes)");
  }
  const std::string coding = req.get_header_value("Content-Encoding");
  if (req.get_header_value_count("Content-Encoding") > 1 ||
      (!coding.empty() && coding != "identity" && coding != "gzip" && coding != "deflate" && coding != "br"))
    return bad(415, "a request body may be sent as it is or with one Content-Encoding: gzip, deflate or br");
  return std::nullopt;
}

bool body_left_unread(const httplib::Request& req) {
  return (req.method == "GET" || req.method == "HEAD" || req.method == "OPTIONS") && has_body(req);
}

std::optional<Problem> read_body(httplib::Request& req, const httplib::ContentReader& read, size_t max_body_bytes) {
  bool too_large = false;
  const auto over = [&](size_t have, size_t more) {
    too_large = more > max_body_bytes - std::min(have, max_body_bytes);
    return too_large;
  };
  bool ok = true;
  if (req.is_multipart_form_data()) {
    size_t total = 0;
    httplib::MultipartFormDataMap::iterator current = req.files.end();
    ok = read(
        [&](const httplib::MultipartFormData& part) {
          total += part.name.size() + part.filename.size() + part.content_type.size();
          if (over(0, total)) return false;
          current = req.files.emplace(part.name, part);
          return true;
        },
        [&](const char* data, size_t n) {
          if (over(total, n)) return false;
          total += n;
          current->second.content.append(data, n);
          return true;
        });
  } else {
    // A declared length is known to be within the limit (check_request_head): one allocation instead of doublings.
    if (!req.has_header("Content-Encoding") || req.get_header_value("Content-Encoding") == "identity") {
      const std::string length = req.get_header_value("Content-Length");
      uint64_t n = 0;
      std::from_chars(length.data(), length.data() + length.size(), n);
      req.body.reserve(static_cast<size_t>(std::min<uint64_t>(n, max_body_bytes)));
    }
    ok = read([&](const char* data, size_t n) {
      if (over(req.body.size(), n)) return false;
      req.body.append(data, n);
      return true;
    });
  }
  if (ok) return std::nullopt;
  req.body.clear();
  req.body.shrink_to_fit();
  req.files.clear();
  const std::string limit = std::to_string(max_body_bytes);
  if (too_large || HttpTransport::read_failure() == ReadFailure::kTooLarge)
    return bad(413, "the request body exceeds the limit of " + limit + " bytes (--max-body-bytes)" +
                        (req.has_header("Content-Encoding") ? " once decompressed" : ""));
  if (HttpTransport::read_failure() == ReadFailure::kTooSlow)
    return bad(408,
               "the request body did not arrive in time (each read within the read timeout, on average at "
               "least --min-transfer-rate)");
  return bad(400,
             req.is_multipart_form_data()
                 ? "the multipart body is malformed (or cut short)"
                 : "the request body could not be read: malformed chunked framing or compressed data, or cut short");
}

}  // namespace tessera::server
