// Request bodies within --max-body-bytes however they arrive. A request's head is judged before any of its body is
// read (RFC 9110 and RFC 9112: one Host, one Content-Length, a transfer coding this server decodes and never with a
// Content-Length, a content coding it decodes, a declared length within the limit); the body is then read as it
// arrives, after chunked decoding and decompression, and refused with 413 the moment the decoded bytes pass the limit.
// After any refusal the body is left unread and the connection must close after the answer.
#pragma once

#include <httplib.h>

#include <cstddef>
#include <optional>
#include <string_view>

#include "server/base/problem.h"

namespace tessera::server {

// Nothing, or 501 for a method this server does not implement (GET, HEAD, POST, PATCH, DELETE, PUT and OPTIONS are
// the ones it does).
std::optional<Problem> check_method(std::string_view method);

// Nothing, or why the request is refused without reading its body: 400 (framing), 413 (declared length above the
// limit), 415 (content coding), 501 (method or transfer coding this server does not implement).
std::optional<Problem> check_request_head(const httplib::Request& req, size_t max_body_bytes);

// Whether a body follows the head (a Transfer-Encoding, or a Content-Length above 0). A request answered without its
// body being read must close its connection after the answer, or the body would be read as the next request.
bool has_body(const httplib::Request& req);
// Whether a body follows the head that cpp-httplib does not read for this method (a GET with a Content-Length).
bool body_left_unread(const httplib::Request& req);

// Reads the body through `read` (decoded) into req.body, or into req.files for multipart/form-data, at most
// `max_body_bytes` of it. Nothing, or the problem to answer: 413 past the limit, 408 when the client sent too slowly,
// 400 when the framing, the compressed data or the multipart document is malformed.
std::optional<Problem> read_body(httplib::Request& req, const httplib::ContentReader& read, size_t max_body_bytes);

}  // namespace tessera::server
