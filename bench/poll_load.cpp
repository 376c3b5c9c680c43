// tessera-poll-load: GET requests to one loopback URL at a fixed rate, on a few keep-alive connections, for a bounded
// time; prints how many were sent, the rate achieved, the status codes, the latency (p50, p99, max) and its own CPU
// time. Requests follow an absolute schedule (request k of connection c at t0 + (k * N + c) / rate), so a slow
// answer is followed by catching up, not by a lower rate; a request that starts more than 1 ms after its slot
// counts as late. SIGINT or SIGTERM ends it early with the same summary.
//
//   tessera-poll-load [--rate N] [--connections N] [--duration S] http://127.0.0.1:PORT/PATH
//
// TESSERA_TOKEN, when set, goes along as "Authorization: Bearer". Only loopback hosts are accepted: it is a
// benchmark of the daemon on this machine, never a load generator against another one.
#include <httplib.h>
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <thread>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

std::atomic<bool> g_stop{false};  // lock-free: set from the signal handler

void on_signal(int) {
  g_stop.store(true);
}

struct Options {
  double rate = 1000;  // requests per second, all connections together
  int connections = 2;
  double duration_s = 10;
  std::string origin;  // "http://127.0.0.1:PORT"
  std::string path;    // "/v1/jobs/..."
};

struct ConnectionResult {
  std::vector<float> latency_us;
  std::map<std::string, uint64_t> outcomes;  // "200", "404", or the client error ("Connection", "Read", ...)
  uint64_t late = 0;
  Clock::time_point last_done{};
};

[[noreturn]] void usage(const char* why) {
  if (why) std::fprintf(stderr, "tessera-poll-load: %s\n", why);
  std::fprintf(stderr,
               "usage: tessera-poll-load [--rate N] [--connections N] [--duration S] http://127.0.0.1:PORT/PATH\n"
               "  --rate N         requests per second over all connections (default 1000)\n"
               "  --connections N  keep-alive connections, one thread each (default 2)\n"
               "  --duration S     seconds to run at most (default 10; SIGINT/SIGTERM end it earlier)\n");
  std::exit(2);
}

bool is_loopback(const std::string& host) {
  return host == "localhost" || host == "[::1]" || host.rfind("127.", 0) == 0;
}

Options parse(int argc, char** argv) {
  Options o;
  std::string url;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> double {
      if (i + 1 >= argc) usage((a + " needs a value").c_str());
      char* end = nullptr;
      const double v = std::strtod(argv[++i], &end);
      if (end == argv[i] || *end != '\0' || !(v > 0)) usage((a + " needs a positive number").c_str());
      return v;
    };
    if (a == "--rate") {
      o.rate = value();
    } else if (a == "--connections") {
      o.connections = static_cast<int>(value());
    } else if (a == "--duration") {
      o.duration_s = value();
    } else if (a == "-h" || a == "--help") {
      usage(nullptr);
    } else if (url.empty() && a.rfind("http://", 0) == 0) {
      url = a;
    } else {
      usage(("unexpected argument " + a).c_str());
    }
  }
  if (url.empty()) usage("no URL");
  if (o.connections < 1 || o.connections > 64) usage("--connections must be in [1, 64]");
  if (o.duration_s > 3600) usage("--duration must be at most 3600 s");
  const size_t slash = url.find('/', 7);
  o.origin = url.substr(0, slash);
  o.path = slash == std::string::npos ? "/" : url.substr(slash);
  std::string host = o.origin.substr(7);
  if (host.rfind('[', 0) == 0)
    host = host.substr(0, host.find(']') + 1);
  else
    host = host.substr(0, host.find(':'));
  if (!is_loopback(host)) usage(("only loopback hosts (127.0.0.0/8, localhost, [::1]), not " + host).c_str());
  return o;
}

void run_connection(const Options& o, int index, Clock::time_point t0, ConnectionResult& out) {
  httplib::Client client(o.origin);
  client.set_keep_alive(true);
  client.set_connection_timeout(2, 0);
  client.set_read_timeout(5, 0);
  httplib::Headers headers;
  if (const char* token = std::getenv("TESSERA_TOKEN"); token && *token)
    headers.emplace("Authorization", std::string("Bearer ") + token);

  const auto period = std::chrono::duration<double>(1.0 / o.rate);
  const auto end = t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.duration_s));
  out.latency_us.reserve(static_cast<size_t>(o.rate * o.duration_s / o.connections) + 16);
  for (uint64_t k = 0;; ++k) {
    const auto slot =
        t0 + std::chrono::duration_cast<Clock::duration>(period * static_cast<double>(k * o.connections + index));
    if (slot >= end) break;
    // Sleeps in steps of at most 100 ms so that a signal ends a slow schedule promptly.
    while (!g_stop.load() && Clock::now() < slot)
      std::this_thread::sleep_until(std::min(slot, Clock::now() + std::chrono::milliseconds(100)));
    if (g_stop.load()) break;
    const auto start = Clock::now();
    if (start - slot > std::chrono::milliseconds(1)) ++out.late;
    auto result = client.Get(o.path, headers);
    const auto done = Clock::now();
    out.last_done = done;
    out.latency_us.push_back(std::chrono::duration<float, std::micro>(done - start).count());
    ++out.outcomes[result ? std::to_string(result->status) : httplib::to_string(result.error())];
  }
}

double cpu_ms() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  auto ms = [](const timeval& t) { return t.tv_sec * 1e3 + t.tv_usec / 1e3; };
  return ms(ru.ru_utime) + ms(ru.ru_stime);
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  std::signal(SIGPIPE, SIG_IGN);

  std::vector<ConnectionResult> results(static_cast<size_t>(o.connections));
  const double cpu_before = cpu_ms();
  const auto t0 = Clock::now() + std::chrono::milliseconds(20);  // every thread is started by then
  std::vector<std::thread> threads;
  for (int c = 0; c < o.connections; ++c)
    threads.emplace_back(run_connection, std::cref(o), c, t0, std::ref(results[static_cast<size_t>(c)]));
  for (std::thread& t : threads) t.join();
  const double cpu = cpu_ms() - cpu_before;

  std::vector<float> latency;
  std::map<std::string, uint64_t> outcomes;
  uint64_t late = 0;
  Clock::time_point last = t0;
  for (const ConnectionResult& r : results) {
    latency.insert(latency.end(), r.latency_us.begin(), r.latency_us.end());
    for (const auto& [k, n] : r.outcomes) outcomes[k] += n;
    late += r.late;
    last = std::max(last, r.last_done);
  }
  const uint64_t sent = latency.size();
  const double elapsed_s = std::max(1e-9, std::chrono::duration<double>(last - t0).count());
  std::sort(latency.begin(), latency.end());
  auto quantile_ms = [&](double q) {
    if (latency.empty()) return 0.0;
    const size_t i = std::min(latency.size() - 1, static_cast<size_t>(q * static_cast<double>(latency.size())));
    return latency[i] / 1e3;
  };

  std::printf("url            %s%s\n", o.origin.c_str(), o.path.c_str());
  std::printf("target         %g requests/s on %d connections for at most %g s\n", o.rate, o.connections, o.duration_s);
  std::printf("sent           %llu requests in %.2f s: %.1f requests/s (%llu started > 1 ms after their slot)\n",
              static_cast<unsigned long long>(sent), elapsed_s, static_cast<double>(sent) / elapsed_s,
              static_cast<unsigned long long>(late));
  std::printf("status        ");
  for (const auto& [k, n] : outcomes) std::printf(" %s: %llu", k.c_str(), static_cast<unsigned long long>(n));
  std::printf("\n");
  std::printf("latency_ms     p50 %.3f  p99 %.3f  max %.3f\n", quantile_ms(0.50), quantile_ms(0.99),
              latency.empty() ? 0.0 : latency.back() / 1e3);
  std::printf("client_cpu_ms  %.0f (%.1f us a request)\n", cpu, sent ? cpu * 1e3 / static_cast<double>(sent) : 0.0);
  const bool all_ok = std::all_of(outcomes.begin(), outcomes.end(), [](const auto& kv) { return kv.first == "200"; });
  return sent > 0 && all_ok ? 0 : 1;
}
