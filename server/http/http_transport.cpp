#include "server/http/http_transport.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <vector>

#include "server/base/log.h"
#include "server/base/problem.h"
#include "server/http/request_head.h"

namespace tessera::server {

namespace {

using Clock = std::chrono::steady_clock;

Clock::duration seconds(double s) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

// Milliseconds from now to `deadline`, at least 0, for poll() and epoll_wait().
int millis_until(Clock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
  return static_cast<int>(std::clamp<int64_t>(left, 0, 60'000));
}

// Waits until `fd` is ready for `events` or the deadline passes; false on timeout or error.
bool wait_ready(int fd, short events, Clock::time_point deadline) {
  for (;;) {
    pollfd p{fd, events, 0};
    const int n = ::poll(&p, 1, millis_until(deadline));
    if (n > 0) return (p.revents & (events | POLLHUP | POLLERR)) != 0;
    if (n == 0) {
      if (Clock::now() >= deadline) return false;
      continue;
    }
    if (errno != EINTR) return false;
  }
}

void address_of(int fd, bool peer, std::string& ip, int& port) {
  sockaddr_storage addr{};
  socklen_t len = sizeof addr;
  const int r = peer ? ::getpeername(fd, reinterpret_cast<sockaddr*>(&addr), &len)
                     : ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  if (r != 0) return;
  char text[INET6_ADDRSTRLEN] = {};
  if (addr.ss_family == AF_INET) {
    const auto* a = reinterpret_cast<const sockaddr_in*>(&addr);
    ::inet_ntop(AF_INET, &a->sin_addr, text, sizeof text);
    port = ntohs(a->sin_port);
  } else if (addr.ss_family == AF_INET6) {
    const auto* a = reinterpret_cast<const sockaddr_in6*>(&addr);
    ::inet_ntop(AF_INET6, &a->sin6_addr, text, sizeof text);
    port = ntohs(a->sin6_port);
  }
  ip = text;
}

const char* reason_phrase(int status) {
  switch (status) {
    case 400:
      return "Bad Request";
    case 408:
      return "Request Timeout";
    case 429:
      return "Too Many Requests";
    case 431:
      return "Request Header Fields Too Large";
    case 501:
      return "Not Implemented";
    case 503:
      return "Service Unavailable";
    default:
      return "Error";
  }
}

// A whole response for a request the transport refuses itself; the connection closes after it.
std::string refusal(int status, const std::string& detail, int retry_after_s) {
  const std::string body = Problem{status, detail, std::nullopt}.to_json().dump();
  std::string out = "HTTP/1.1 " + std::to_string(status) + " " + reason_phrase(status) + "\r\n";
  out += std::string("Content-Type: ") + kProblemMediaType + "\r\n";
  out += "Content-Length: " + std::to_string(body.size()) + "\r\n";
  if (retry_after_s > 0) out += "Retry-After: " + std::to_string(retry_after_s) + "\r\n";
  out += "Connection: close\r\n\r\n";
  return out + body;
}

// A pool of at most `max` threads, started as they are first needed. Ordinary requests queue when every thread is
// busy; long-lived ones are refused instead (a queued event stream would wait for another to end).
class Workers {
 public:
  Workers(int max, bool queue_when_busy) : max_(static_cast<size_t>(std::max(1, max))), queue_(queue_when_busy) {}
  ~Workers() { stop(); }

  bool submit(std::function<void()> task) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return false;
    if (!queue_ && busy_ + tasks_.size() >= max_) return false;
    tasks_.push_back(std::move(task));
    if (idle_ > tasks_.size() - 1) {
      wake_.notify_one();
      return true;
    }
    if (threads_.size() < max_) {
      try {
        threads_.emplace_back([this] { loop(); });
      } catch (const std::system_error&) {
        // No thread could be started: the task waits for one that exists, or is refused when there is none.
        if (threads_.empty()) {
          tasks_.pop_back();
          return false;
        }
      }
    }
    return true;
  }

  // Runs what is queued, then ends the threads.
  void stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
    for (std::thread& t : threads_)
      if (t.joinable()) t.join();
    threads_.clear();
  }

  size_t busy() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return busy_;
  }

 private:
  void loop() {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      ++idle_;
      wake_.wait(lock, [this] { return stopping_ || !tasks_.empty(); });
      --idle_;
      if (tasks_.empty()) return;  // stopping, nothing left
      std::function<void()> task = std::move(tasks_.front());
      tasks_.pop_front();
      ++busy_;
      lock.unlock();
      task();
      lock.lock();
      --busy_;
    }
  }

  const size_t max_;
  const bool queue_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::function<void()>> tasks_;
  std::vector<std::thread> threads_;
  size_t idle_ = 0, busy_ = 0;
  bool stopping_ = false;
};

// One client connection. While it waits for a request head it belongs to the reactor thread; while a request is
// handled, to one worker; never to both.
struct Connection {
  int fd = -1;
  std::string client;  // the remote address: what the per-client cap counts
  std::string remote_ip, local_ip;
  int remote_port = 0, local_port = 0;

  std::string buffer;  // bytes read and not yet consumed (buffer[consumed..])
  size_t consumed = 0;
  size_t head_end = 0;      // buffer index just past the blank line of the head of the request being handled
  size_t head_checked = 0;  // bytes of the next request's head, from `consumed`, that scan_head found well-formed
  Clock::time_point deadline;
  bool started = false;    // a byte of the next request has arrived
  bool lingering = false;  // answered and closing: draining what the client still sends (linger())
  Clock::time_point linger_end;
  int served = 0;

  // The request being handled.
  Clock::time_point dispatched;
  uint64_t body_bytes = 0;
  bool first_write = true;
  Clock::time_point write_start;
  uint64_t written = 0;
  bool long_lived = false;
  bool close_requested = false;
  ReadFailure failure = ReadFailure::kNone;

  size_t pending() const { return buffer.size() - consumed; }
  void compact() {
    if (consumed == 0) return;
    buffer.erase(0, consumed);
    head_end = head_end > consumed ? head_end - consumed : 0;
    consumed = 0;
  }
};

thread_local Connection* t_connection = nullptr;

}  // namespace

struct HttpTransport::Impl {
  HttpTransport& server;
  TransportLimits limits;
  Workers requests;
  Workers bodies;
  Workers streams;
  int epoll_fd = -1;
  int wake_fd = -1;
  std::thread reactor;
  std::atomic<bool> stopping{false};
  bool stopped = false;

  std::mutex mutex;  // guards what follows
  std::vector<std::unique_ptr<Connection>> incoming;
  std::unordered_map<std::string, int> per_client;
  int64_t connections = 0;
  int64_t lingering = 0;
  bool reactor_done = false;
  struct Throttle {
    Clock::time_point last;
    int64_t count = 0;
    bool logged = false;
  };
  std::unordered_map<std::string, Throttle> throttles;
  std::atomic<int64_t> refused_total{0}, timed_out_total{0};

  // Reactor-owned.
  std::unordered_map<int, std::unique_ptr<Connection>> waiting;

  Impl(HttpTransport& s, TransportLimits l)
      : server(s),
        limits(std::move(l)),
        requests(limits.request_threads, true),
        bodies(limits.body_threads, true),
        streams(limits.stream_threads, false) {
    epoll_fd = ::epoll_create1(EPOLL_CLOEXEC);
    wake_fd = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
    if (epoll_fd < 0 || wake_fd < 0) throw std::system_error(errno, std::generic_category(), "epoll/eventfd");
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.fd = wake_fd;
    ::epoll_ctl(epoll_fd, EPOLL_CTL_ADD, wake_fd, &ev);
    reactor = std::thread([this] { reactor_loop(); });
  }

  ~Impl() {
    stop();
    ::close(epoll_fd);
    ::close(wake_fd);
  }

  void wake() {
    const uint64_t one = 1;
    [[maybe_unused]] ssize_t n = ::write(wake_fd, &one, sizeof one);
  }

  // Stops taking connections: the reactor closes the ones waiting, workers finish their requests and close theirs.
  void stop() {
    if (stopped) return;
    stopped = true;
    stopping = true;
    wake();
    if (reactor.joinable()) reactor.join();
    requests.stop();
    bodies.stop();
    streams.stop();
  }

  // ---- accepting -------------------------------------------------------------------------------------------------

  void accept_connection(int fd) {
    if (stopping) {
      ::close(fd);
      return;
    }
    const int flags = ::fcntl(fd, F_GETFL, 0);
    ::fcntl(fd, F_SETFL, flags | O_NONBLOCK);
    const int one = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    auto c = std::make_unique<Connection>();
    c->fd = fd;
    address_of(fd, true, c->remote_ip, c->remote_port);
    address_of(fd, false, c->local_ip, c->local_port);
    c->client = c->remote_ip;

    int status = 0;
    std::string detail;
    {
      std::lock_guard<std::mutex> lock(mutex);
      int& mine = per_client[c->client];
      if (connections >= limits.max_connections) {
        status = 503;
        detail = "the server has " + std::to_string(connections) + " connections open, its limit (--max-connections)";
      } else if (limits.max_connections_per_client > 0 && mine >= limits.max_connections_per_client) {
        status = 429;
        detail = "this address has " + std::to_string(mine) +
                 " connections open, the most one client may have (--max-connections-per-client)";
      } else {
        ++mine;
        ++connections;
      }
      if (status != 0 && mine == 0) per_client.erase(c->client);
    }
    if (status != 0) {
      ++refused_total;
      refuse(std::move(c), status, detail, 1, /*counted=*/false, "connection refused");
      return;
    }
    c->deadline = Clock::now() + seconds(limits.header_timeout_s);
    hand_to_reactor(std::move(c));
  }

  // One log line per kind of refusal every 10 s at most, with how many there were: a flood of them must not flood the
  // log.
  void log_refusal(const char* what, int status, const std::string& client) {
    std::unique_lock<std::mutex> lock(mutex);
    Throttle& t = throttles[what];
    ++t.count;
    const Clock::time_point now = Clock::now();
    if (t.logged && now - t.last < std::chrono::seconds(10)) return;
    const int64_t count = t.count;
    t = {now, 0, true};
    lock.unlock();
    log(LogLevel::kWarn, what, {{"status", status}, {"client", client}, {"count", count}});
  }

  void hand_to_reactor(std::unique_ptr<Connection> c) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (!reactor_done) {
        incoming.push_back(std::move(c));
        c = nullptr;
      }
    }
    if (c) return close_connection(std::move(c));
    wake();
  }

  // Logs (throttled) and writes the refusal, then lingers (below).
  void refuse(std::unique_ptr<Connection> c, int status, const std::string& detail, int retry_after_s, bool counted,
              const char* what) {
    log_refusal(what, status, c->client);
    const std::string answer = refusal(status, detail, retry_after_s);
    [[maybe_unused]] ssize_t n = ::send(c->fd, answer.data(), answer.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    linger(std::move(c), counted);
  }

  // Closes the sending side and reads and drops what the client still sends, until it closes or stops sending for a
  // moment (at most kLingerTotal): closing a socket with unread data resets the connection, and a client that writes
  // all of its body before it reads (most do) would lose the answer. As nginx's lingering_close.
  static constexpr auto kLingerIdle = std::chrono::seconds(2);
  static constexpr auto kLingerTotal = std::chrono::seconds(10);
  void linger(std::unique_ptr<Connection> c, bool counted) {
    ::shutdown(c->fd, SHUT_WR);
    if (counted) release(*c);
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (lingering >= 256 || stopping) {
        ::close(c->fd);
        return;
      }
      ++lingering;
    }
    c->lingering = true;
    c->linger_end = Clock::now() + kLingerTotal;
    c->deadline = Clock::now() + kLingerIdle;
    c->buffer.clear();
    c->buffer.shrink_to_fit();
    c->consumed = 0;
    hand_to_reactor(std::move(c));
  }

  void release(const Connection& c) {
    std::lock_guard<std::mutex> lock(mutex);
    --connections;
    auto it = per_client.find(c.client);
    if (it != per_client.end() && --it->second <= 0) per_client.erase(it);
  }

  void close_connection(std::unique_ptr<Connection> c) {
    if (c->lingering) {
      std::lock_guard<std::mutex> lock(mutex);
      --lingering;
    } else {
      release(*c);
    }
    ::close(c->fd);
  }

  // ---- the reactor: waiting for request heads ------------------------------------------------------------------

  void reactor_loop() {
    std::vector<epoll_event> events(128);
    while (!stopping) {
      Clock::time_point next = Clock::now() + std::chrono::seconds(1);
      for (const auto& [fd, c] : waiting) next = std::min(next, c->deadline);
      const int n = ::epoll_wait(epoll_fd, events.data(), static_cast<int>(events.size()), millis_until(next));
      for (int i = 0; i < n; ++i) {
        const int fd = events[static_cast<size_t>(i)].data.fd;
        if (fd == wake_fd) {
          uint64_t count;
          [[maybe_unused]] ssize_t r = ::read(wake_fd, &count, sizeof count);
          continue;
        }
        auto it = waiting.find(fd);
        if (it != waiting.end()) on_readable(it);
      }
      take_incoming();
      expire();
    }
    for (auto& [fd, c] : waiting) close_connection(std::move(c));
    waiting.clear();
    std::vector<std::unique_ptr<Connection>> rest;
    {
      std::lock_guard<std::mutex> lock(mutex);
      rest.swap(incoming);
      reactor_done = true;
    }
    for (auto& c : rest) close_connection(std::move(c));
  }

  void take_incoming() {
    std::vector<std::unique_ptr<Connection>> list;
    {
      std::lock_guard<std::mutex> lock(mutex);
      list.swap(incoming);
    }
    for (auto& c : list) {
      // A kept-alive connection may hold the next request already (pipelining).
      if (!c->lingering && c->pending() > 0) {
        if (!c->started) start_head(*c);
        if (head_complete_or_refused(c)) continue;
      }
      epoll_event ev{};
      ev.events = EPOLLIN | EPOLLRDHUP;
      ev.data.fd = c->fd;
      if (::epoll_ctl(epoll_fd, EPOLL_CTL_ADD, c->fd, &ev) != 0) {
        close_connection(std::move(c));
        continue;
      }
      const int fd = c->fd;
      waiting.emplace(fd, std::move(c));
    }
  }

  // The first byte of a request: its head is due within the header timeout. A new connection's deadline runs from
  // the accept already (a client cannot wait first and then start its slow head).
  void start_head(Connection& c) {
    c.started = true;
    if (c.served > 0) c.deadline = Clock::now() + seconds(limits.header_timeout_s);
  }

  void unwatch(int fd) { ::epoll_ctl(epoll_fd, EPOLL_CTL_DEL, fd, nullptr); }

  void on_readable(std::unordered_map<int, std::unique_ptr<Connection>>::iterator it) {
    Connection& c = *it->second;
    char chunk[16 << 10];
    bool eof = false;
    for (;;) {
      const ssize_t n = ::recv(c.fd, chunk, sizeof chunk, MSG_DONTWAIT);
      if (n > 0) {
        if (!c.lingering) c.buffer.append(chunk, static_cast<size_t>(n));
        if (c.pending() > limits.max_header_bytes) break;
        continue;
      }
      if (n == 0)
        eof = true;
      else if (errno == EINTR)
        continue;
      else if (errno != EAGAIN && errno != EWOULDBLOCK)
        eof = true;
      break;
    }
    if (c.lingering) {
      if (eof) return drop(it);
      c.deadline = std::min(Clock::now() + kLingerIdle, c.linger_end);
      return;
    }
    if (!c.started && c.pending() > 0) start_head(c);
    std::unique_ptr<Connection> owned = std::move(it->second);
    waiting.erase(it);
    if (head_complete_or_refused(owned)) {
      if (owned) unwatch(owned->fd);
      return;
    }
    if (eof) {  // the client went away before its request was whole
      unwatch(owned->fd);
      close_connection(std::move(owned));
      return;
    }
    const int fd = owned->fd;
    waiting.emplace(fd, std::move(owned));
  }

  void drop(std::unordered_map<int, std::unique_ptr<Connection>>::iterator it) {
    unwatch(it->first);
    std::unique_ptr<Connection> c = std::move(it->second);
    waiting.erase(it);
    close_connection(std::move(c));
  }

  // True when the connection left the reactor: its head is whole and it went to a worker, or it was refused. The
  // caller still has to take its fd out of epoll when it was watched.
  bool head_complete_or_refused(std::unique_ptr<Connection>& c) {
    // A server should ignore empty lines before a request line (RFC 9112, section 2.2).
    while (c->pending() >= 2 && c->buffer.compare(c->consumed, 2, "\r\n") == 0) c->consumed += 2;
    const std::string_view pending(c->buffer.data() + c->consumed, c->pending());
    HeadScan scan = scan_head(pending.substr(0, limits.max_header_bytes), c->head_checked);
    c->head_checked = scan.checked;
    if (!scan.problem && scan.length > 0 && limits.check_method) scan.problem = limits.check_method(scan.head.method);
    if (scan.problem) {
      unwatch(c->fd);
      refuse(std::move(c), scan.problem->status, scan.problem->detail, 0, true, "request head refused");
      return true;
    }
    if (scan.length == 0) {
      if (c->pending() <= limits.max_header_bytes) return false;
      unwatch(c->fd);
      refuse(std::move(c), 431,
             "the request line and headers exceed " + std::to_string(limits.max_header_bytes) + " bytes", 0, true,
             "request head too large");
      return true;
    }
    c->head_end = c->consumed + scan.length;
    unwatch(c->fd);
    dispatch(std::move(c), scan.head);
    return true;
  }

  void expire() {
    const Clock::time_point now = Clock::now();
    std::vector<int> late;
    for (const auto& [fd, c] : waiting)
      if (c->deadline <= now) late.push_back(fd);
    for (int fd : late) {
      auto it = waiting.find(fd);
      std::unique_ptr<Connection> c = std::move(it->second);
      waiting.erase(it);
      unwatch(fd);
      if (c->lingering || !c->started) {  // an idle kept-alive connection, or a refusal drained
        close_connection(std::move(c));
        continue;
      }
      ++timed_out_total;
      refuse(std::move(c), 408,
             "the request line and headers did not arrive within " + std::to_string(limits.header_timeout_s) +
                 " s (--header-timeout-s)",
             0, true, "request head timed out");
    }
  }

  // ---- workers -------------------------------------------------------------------------------------------------

  // The pool a request goes to: an event stream's own; the body readers' when its body has not all arrived with its
  // head (the worker would wait for the client, at a pace the client chooses); else the ordinary one, whose workers
  // therefore never wait for a body, however slowly clients send theirs.
  Workers& pool_for(const Connection& c, const RequestHead& head) {
    if (c.long_lived) return streams;
    return body_arrived(head, c.buffer.size() - c.head_end) ? requests : bodies;
  }

  // `head` views the connection's buffer, which is the worker's from the moment it has the connection.
  void dispatch(std::unique_ptr<Connection> c, const RequestHead& head) {
    c->long_lived = head.method == "GET" && limits.is_long_lived && limits.is_long_lived(head.target);
    Workers& pool = pool_for(*c, head);
    Connection* raw = c.release();
    if (pool.submit([this, raw] { serve(std::unique_ptr<Connection>(raw)); })) return;
    c.reset(raw);
    if (stopping) return close_connection(std::move(c));
    ++refused_total;
    refuse(std::move(c), 503,
           "the server is sending " + std::to_string(limits.stream_threads) +
               " event streams, its limit (--max-event-streams); poll GET /v1/jobs/{id} or retry later",
           5, true, "event stream refused: every stream thread is busy");
  }

  void serve(std::unique_ptr<Connection> c) {
    c->dispatched = Clock::now();
    c->body_bytes = 0;
    c->first_write = true;
    c->written = 0;
    c->close_requested = false;
    c->failure = ReadFailure::kNone;
    const bool last = stopping || static_cast<size_t>(c->served + 1) >= server.keep_alive_max_count_;
    bool client_closes = false;
    bool ok = false;
    {
      Stream stream(*this, *c);
      t_connection = c.get();
      try {
        ok = server.process_request(stream, last, client_closes, nullptr);
      } catch (...) {
        ok = false;  // process_request catches what handlers throw; anything else ends the connection
      }
      t_connection = nullptr;
    }
    ++c->served;
    if (!ok || c->failure == ReadFailure::kClosed || c->failure == ReadFailure::kTooSlow) {
      return close_connection(std::move(c));  // nothing more to say to this client
    }
    if (last || client_closes || c->close_requested || c->failure != ReadFailure::kNone || stopping) {
      return linger(std::move(c), true);
    }
    c->compact();
    if (c->buffer.capacity() > (64u << 10) && c->pending() < (16u << 10)) c->buffer.shrink_to_fit();
    c->started = false;
    c->head_checked = 0;
    c->deadline = Clock::now() + std::chrono::seconds(server.keep_alive_timeout_sec_);
    hand_to_reactor(std::move(c));
  }

  // The stream cpp-httplib reads a request from and writes its response to: the connection's buffer first (the head
  // the reactor read, and whatever followed it), then the socket, each read and write within the read/write
  // timeouts and, but for long-lived responses, at the minimum average rate after the grace period.
  class Stream final : public httplib::Stream {
   public:
    Stream(Impl& impl, Connection& c) : impl_(impl), c_(c) {}

    bool is_readable() const override {
      return c_.pending() > 0 || wait_ready(c_.fd, POLLIN, Clock::now() + read_timeout());
    }

    bool is_writable() const override {
      if (!wait_ready(c_.fd, POLLOUT, Clock::now() + write_timeout())) return false;
      // As cpp-httplib's own stream: a client that has closed its side is gone (an event stream ends).
      pollfd p{c_.fd, POLLIN, 0};
      if (::poll(&p, 1, 0) <= 0) return true;
      char byte;
      return ::recv(c_.fd, &byte, 1, MSG_PEEK | MSG_DONTWAIT) != 0;
    }

    ssize_t read(char* ptr, size_t size) override {
      if (c_.pending() == 0) {
        const ssize_t got = fill();
        if (got <= 0) return got;
      }
      size_t n = std::min(size, c_.pending());
      // Bytes past the head are the body's (chunk framing included).
      const uint64_t body_before = c_.body_bytes;
      const size_t at = c_.consumed;
      const uint64_t body_in_n = at + n > c_.head_end ? at + n - std::max(at, c_.head_end) : 0;
      const uint64_t cap = impl_.limits.max_body_wire_bytes;
      if (cap > 0 && body_before + body_in_n > cap) {
        c_.failure = ReadFailure::kTooLarge;
        return -1;
      }
      std::memcpy(ptr, c_.buffer.data() + at, n);
      c_.consumed += n;
      c_.body_bytes += body_in_n;
      if (c_.consumed == c_.buffer.size()) {
        c_.buffer.clear();
        c_.head_end = c_.head_end > c_.consumed ? c_.head_end - c_.consumed : 0;
        c_.consumed = 0;
      }
      return static_cast<ssize_t>(n);
    }

    ssize_t write(const char* ptr, size_t size) override {
      if (c_.first_write) {
        c_.first_write = false;
        c_.write_start = Clock::now();
        // The connection closes after this response (a body left unread): its head says so (RFC 9112, 9.6) in place
        // of the Keep-Alive line cpp-httplib wrote into it.
        if (c_.close_requested) return write_closing_head(ptr, size);
      }
      return send_some(ptr, size);
    }

    ssize_t send_some(const char* ptr, size_t size) {
      Clock::time_point deadline = Clock::now() + write_timeout();
      if (!c_.long_lived) deadline = std::min(deadline, rate_deadline(c_.write_start, c_.written));
      for (;;) {
        const ssize_t n = ::send(c_.fd, ptr, size, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (n >= 0) {
          c_.written += static_cast<uint64_t>(n);
          return n;
        }
        if (errno == EINTR) continue;
        if (errno != EAGAIN && errno != EWOULDBLOCK) return -1;
        if (!wait_ready(c_.fd, POLLOUT, deadline)) {
          ++impl_.timed_out_total;
          c_.close_requested = true;
          return -1;
        }
      }
    }

    // Sends all of a response head with "Keep-Alive: ..." replaced by "Connection: close"; -1 when it cannot.
    ssize_t write_closing_head(const char* ptr, size_t size) {
      std::string head(ptr, size);
      const size_t at = head.find("\r\nKeep-Alive: ");
      if (at != std::string::npos && head.compare(0, 5, "HTTP/") == 0) {
        const size_t end = head.find("\r\n", at + 2);
        head.replace(at + 2, end - at - 2, "Connection: close");
      }
      for (size_t sent = 0; sent < head.size();) {
        const ssize_t n = send_some(head.data() + sent, head.size() - sent);
        if (n <= 0) return -1;
        sent += static_cast<size_t>(n);
      }
      return static_cast<ssize_t>(size);
    }

    void get_remote_ip_and_port(std::string& ip, int& port) const override {
      ip = c_.remote_ip;
      port = c_.remote_port;
    }
    void get_local_ip_and_port(std::string& ip, int& port) const override {
      ip = c_.local_ip;
      port = c_.local_port;
    }
    int socket() const override { return c_.fd; }

   private:
    Clock::duration read_timeout() const {
      return std::chrono::seconds(impl_.server.read_timeout_sec_) +
             std::chrono::microseconds(impl_.server.read_timeout_usec_);
    }
    Clock::duration write_timeout() const {
      return std::chrono::seconds(impl_.server.write_timeout_sec_) +
             std::chrono::microseconds(impl_.server.write_timeout_usec_);
    }
    // When `bytes` moved since `start` would fall below the minimum average rate.
    Clock::time_point rate_deadline(Clock::time_point start, uint64_t bytes) const {
      const TransportLimits& l = impl_.limits;
      if (l.min_rate_bytes_per_s <= 0) return Clock::time_point::max();
      return start + seconds(l.rate_grace_s + static_cast<double>(bytes) / l.min_rate_bytes_per_s);
    }

    // Reads what the socket has into the buffer: >0 bytes, 0 at the end of the stream, -1 on error or timeout.
    ssize_t fill() {
      if (c_.failure != ReadFailure::kNone) return -1;
      const Clock::time_point deadline =
          std::min(Clock::now() + read_timeout(), rate_deadline(c_.dispatched, c_.body_bytes));
      char chunk[16 << 10];
      for (;;) {
        const ssize_t n = ::recv(c_.fd, chunk, sizeof chunk, MSG_DONTWAIT);
        if (n > 0) {
          c_.buffer.append(chunk, static_cast<size_t>(n));
          return n;
        }
        if (n == 0) {
          c_.failure = ReadFailure::kClosed;
          return 0;
        }
        if (errno == EINTR) continue;
        if (errno != EAGAIN && errno != EWOULDBLOCK) {
          c_.failure = ReadFailure::kClosed;
          return -1;
        }
        if (!wait_ready(c_.fd, POLLIN, deadline)) {
          ++impl_.timed_out_total;
          c_.failure = ReadFailure::kTooSlow;
          return -1;
        }
      }
    }

    Impl& impl_;
    Connection& c_;
  };
};

namespace {

// cpp-httplib runs each accepted connection as a task of this queue, on its accepting thread: the task only hands the
// socket to the reactor (process_and_close_socket), so accepting never waits for a worker.
class AcceptQueue final : public httplib::TaskQueue {
 public:
  explicit AcceptQueue(std::function<void()> on_shutdown) : on_shutdown_(std::move(on_shutdown)) {}
  void enqueue(std::function<void()> fn) override { fn(); }
  void shutdown() override { on_shutdown_(); }

 private:
  std::function<void()> on_shutdown_;
};

}  // namespace

HttpTransport::HttpTransport(TransportLimits limits) : impl_(std::make_unique<Impl>(*this, std::move(limits))) {
  new_task_queue = [this] { return new AcceptQueue([this] { impl_->stop(); }); };
}

HttpTransport::~HttpTransport() {
  impl_->stop();
}

std::optional<int> HttpTransport::bind(const std::string& host, int port) {
  int bound = port;
  if (port == 0) {
    bound = bind_to_any_port(host);
    if (bound <= 0) return std::nullopt;
  } else if (!bind_to_port(host, port)) {
    return std::nullopt;
  }
  // cpp-httplib listens with a backlog of 5: bursts of connections beyond it wait for SYN retransmits (1 s, 3 s, 7 s).
  // listen() again on a listening socket sets its backlog (Linux: inet_listen), capped by net.core.somaxconn.
  const int backlog = impl_->limits.listen_backlog > 0 ? impl_->limits.listen_backlog : SOMAXCONN;
  if (::listen(svr_sock_, backlog) != 0)
    log(LogLevel::kWarn, "cannot raise the listen backlog", {{"backlog", backlog}, {"error", std::strerror(errno)}});
  return bound;
}

TransportStats HttpTransport::stats() const {
  TransportStats s;
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    s.connections = impl_->connections;
  }
  s.refused_total = impl_->refused_total;
  s.timed_out_total = impl_->timed_out_total;
  return s;
}

void HttpTransport::close_after_response() {
  if (t_connection) t_connection->close_requested = true;
}

ReadFailure HttpTransport::read_failure() {
  return t_connection ? t_connection->failure : ReadFailure::kNone;
}

bool HttpTransport::process_and_close_socket(int sock) {
  impl_->accept_connection(sock);
  return true;
}

}  // namespace tessera::server
