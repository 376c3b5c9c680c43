// The connection layer of tesserad, under cpp-httplib's request handling. cpp-httplib 0.11 gives every connection a
// thread of its pool from accept to close, listens with a backlog of 5, reads headers with only a per-recv timeout
// (a client sending one byte a second holds its thread forever) and drops pipelined requests (each request's stream
// has its own read buffer). HttpTransport keeps cpp-httplib's parsing, routing and responses (process_request) and
// replaces what surrounds them:
//  - one thread waits (epoll) on every connection until a whole request head (request line and headers) has arrived,
//    within a deadline from its first byte, and within a size; an idle kept-alive connection waits there too, so
//    neither holds a worker thread;
//  - a head is judged as it arrives (request_head.h): a malformed one is refused before cpp-httplib parses it;
//  - a complete request goes to a worker of one of three pools, so that no kind of request can take the threads
//    another needs: ordinary requests, whose body (if any) arrived with the head; requests whose body is still to
//    come, read by a smaller pool that makes them wait their turn rather than hold every thread while a slow client
//    sends; and long-lived responses (event streams), bounded, beyond which they are refused;
//  - connections are capped in all and per client address; a request body and a response must move at a minimum
//    average rate (after a grace period, as Apache's mod_reqtimeout MinRate), and every read and write at least once
//    per read/write timeout;
//  - the listen backlog is the system's (SOMAXCONN), and bytes read past a request stay for the next one
//    (pipelining, RFC 9112 section 9.3.2).
// What it refuses itself, before any handler runs, it answers with problem+json and closes: 400 (malformed head), 408
// (head too slow), 431 (head too large), 429 (too many connections from one address), 501 (a method refused by
// TransportLimits::check_method), 503 (too many connections or event streams).
#pragma once

#include <httplib.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "server/base/problem.h"

namespace tessera::server {

struct TransportLimits {
  int request_threads = 64;                // workers for ordinary requests (queued beyond)
  int body_threads = 16;                   // workers for requests whose body had not all come with the head (queued)
  int stream_threads = 256;                // workers for long-lived responses; beyond them 503
  int max_connections = 1024;              // open connections in all; beyond them 503
  int max_connections_per_client = 32;     // open connections of one remote address; beyond them 429; 0: no cap
  double header_timeout_s = 10;            // from a request's first byte to the end of its headers; else 408
  size_t max_header_bytes = 32 << 10;      // request line and headers; beyond them 431
  double min_rate_bytes_per_s = 16 << 10;  // bodies and ordinary responses, on average, after the grace period
  double rate_grace_s = 10;
  uint64_t max_body_wire_bytes = 0;  // bytes of one request body as sent (chunk framing included); 0: none
  int listen_backlog = 0;            // 0: SOMAXCONN
  // Whether a request target ("/v1/events?x=1") is answered by a long-lived response.
  std::function<bool(std::string_view target)> is_long_lived;
  // Nothing, or why a request of this method is refused before it is handled (a method the server does not implement).
  std::function<std::optional<Problem>(std::string_view method)> check_method;
};

// Why the body of the request being handled on this thread could not be read (see HttpTransport::read_failure).
enum class ReadFailure { kNone, kTooLarge, kTooSlow, kClosed };

struct TransportStats {
  int64_t connections = 0;      // open now
  int64_t refused_total = 0;    // answered 429/503 at accept, or as an event stream beyond the limit, and closed
  int64_t timed_out_total = 0;  // request heads or transfers that missed their deadline (408 or closed)
};

class HttpTransport : public httplib::Server {
 public:
  explicit HttpTransport(TransportLimits limits);
  ~HttpTransport() override;
  HttpTransport(const HttpTransport&) = delete;
  HttpTransport& operator=(const HttpTransport&) = delete;

  // Binds (port 0: any free port) and listens with the configured backlog; the port, or nothing.
  std::optional<int> bind(const std::string& host, int port);

  TransportStats stats() const;

  // For the handler of the request on this thread: close the connection once the response is written (a body that is
  // refused unread must not be parsed as the next request). Outside a transport's worker it does nothing.
  static void close_after_response();
  // For the handler of the request on this thread: why reading its body failed, if the transport made it fail.
  static ReadFailure read_failure();

 private:
  struct Impl;
  bool process_and_close_socket(int sock) override;

  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera::server
