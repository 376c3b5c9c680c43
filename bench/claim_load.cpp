// Claims per second a PostgreSQL job store sustains (bench/cluster_scaling.sh): JOBS jobs split into UNITS work units
// each, THREADS daemons' worth of store connections (a node name each) claiming a unit (or a merge) and recording its
// end as fast as they can, as render nodes whose units took no time would. Prints the claims (each with its end) per
// second.
//   tessera-claim-load CONNINFO [JOBS=200] [UNITS=20] [THREADS=4]
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "server/base/job_id.h"
#include "server/base/time_format.h"
#include "server/store/postgres_job_store.h"

using namespace tessera::server;

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: tessera-claim-load CONNINFO [JOBS] [UNITS] [THREADS]\n");
    return 2;
  }
  const std::string conninfo = argv[1];
  const int jobs = argc > 2 ? std::atoi(argv[2]) : 200;
  const int units = argc > 3 ? std::atoi(argv[3]) : 20;
  const int threads = argc > 4 ? std::atoi(argv[4]) : 4;
  PostgresJobStore setup(conninfo, "setup");
  for (int i = 0; i < jobs; ++i) {
    JobRecord job;
    job.id = new_job_id();
    job.kind = "scene";
    job.created_at_ms = now_ms();
    job.document = R"({"kind":"scene"})";
    job.settings = R"({"width":1,"height":1})";
    job.outputs = R"(["exr"])";
    job.progress.samples_total = static_cast<uint32_t>(units);
    job.units = units;
    setup.create(job);
  }
  std::atomic<int> claims{0};
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::thread> workers;
  for (int t = 0; t < threads; ++t)
    workers.emplace_back([&, t] {
      PostgresJobStore store(conninfo, "load-" + std::to_string(t));
      while (auto claimed = store.claim_next(now_ms(), 30000)) {
        store.end_run(claimed->id, claimed->epoch, JobState::kSucceeded, now_ms());  // a merge's ends its job
        claims.fetch_add(1);
      }
    });
  for (auto& w : workers) w.join();
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("%d claims (each with its end) by %d connections in %.2f s: %.0f claims/s\n", claims.load(), threads, s,
              claims.load() / s);
  return 0;
}
