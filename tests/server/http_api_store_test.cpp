// The HTTP API when the job store fails (a database locked too long, an I/O error, a full disk) on a route other
// than job creation: the client is told to retry (503, or 507 when the store ran out of space, both with
// Retry-After), not that the daemon broke (500); a request the store refused changed nothing; an open event stream
// ends rather than the daemon. The API runs in-process on a loopback port, over the real SQLite store wrapped so that
// it fails on demand.
#include <gtest/gtest.h>
#include <httplib.h>

#include <atomic>
#include <fstream>
#include <iterator>
#include <memory>
#include <thread>

#include <nlohmann/json.hpp>

#include "renderer/thread_pool.h"
#include "server/base/auth.h"
#include "server/files/assets.h"
#include "server/files/events.h"
#include "server/files/job_files.h"
#include "server/http/http_api.h"
#include "server/jobs/metrics.h"
#include "server/jobs/scheduler.h"
#include "server/store/sqlite_job_store.h"
#include "tests/renderer/vdb_fixture.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using nlohmann::json;

// The real SQLite store, except that while `failure` is set, every read and write (`writes_only`, `reads_only`: only
// those) fails as SQLite would: "database is locked" (kLocked), "database or disk is full" (kFull), or, for a failure
// that is not the store's, a plain std::runtime_error (kOther).
class FlakyStore final : public JobStore {
 public:
  enum class Failure { kNone, kLocked, kFull, kOther };
  explicit FlakyStore(JobStore& inner) : inner_(inner) {}

  std::atomic<Failure> failure{Failure::kNone};
  std::atomic<bool> writes_only{false};
  std::atomic<bool> reads_only{false};
  std::atomic<bool> ends_only{false};  // only the end of a job (a move to succeeded, failed or cancelled) fails
  std::atomic<int> failures{0};        // calls refused so far

  void create(const JobRecord& job) override {
    check(true);
    inner_.create(job);
  }
  std::optional<JobRecord> claim_next(int64_t now_ms, int64_t lease_ms, int max_running_per_owner) override {
    check(true);
    return inner_.claim_next(now_ms, lease_ms, max_running_per_owner);
  }
  bool renew_lease(const std::string& id, int64_t epoch, int64_t now_ms, int64_t lease_ms) override {
    check(true);
    return inner_.renew_lease(id, epoch, now_ms, lease_ms);
  }
  bool update_progress(const std::string& id, int64_t epoch, const JobProgress& p) override {
    check(true);
    return inner_.update_progress(id, epoch, p);
  }
  bool end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms, const std::string& stop_reason,
               const std::string& error) override {
    check(true, is_terminal(to));
    return inner_.end_run(id, epoch, to, now_ms, stop_reason, error);
  }
  bool transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                  const std::string& error, std::optional<JobState> only_from) override {
    check(true, is_terminal(to));
    return inner_.transition(id, to, now_ms, stop_reason, error, only_from);
  }
  bool set_priority(const std::string& id, int priority) override {
    check(true);
    return inner_.set_priority(id, priority);
  }
  void set_warnings(const std::string& id, const std::string& w) override {
    check(true);
    inner_.set_warnings(id, w);
  }
  std::optional<int> queue_position(const std::string& id) override {
    check(false);
    return inner_.queue_position(id);
  }
  std::optional<JobRecord> find_by_idempotency_key(const std::string& owner, const std::string& key) override {
    check(false);
    return inner_.find_by_idempotency_key(owner, key);
  }
  std::map<JobState, int> count_by_state(const std::optional<std::string>& owner) override {
    check(false);
    return inner_.count_by_state(owner);
  }
  std::optional<JobRecord> get(const std::string& id, bool with_document) override {
    check(false);
    return inner_.get(id, with_document);
  }
  std::vector<JobRecord> list(const JobFilter& filter) override {
    check(false);
    return inner_.list(filter);
  }
  bool remove(const std::string& id, std::optional<int64_t> only_finished_before_ms) override {
    check(true);
    return inner_.remove(id, only_finished_before_ms);
  }
  int requeue_running() override {
    check(true);
    return inner_.requeue_running();
  }

 private:
  void check(bool write, bool end = false) {
    const Failure f = failure.load();
    if (f == Failure::kNone || (writes_only.load() && !write) || (reads_only.load() && write) ||
        (ends_only.load() && !end))
      return;
    failures.fetch_add(1);
    if (f == Failure::kLocked) throw JobStoreError("job store: step: database is locked", false);
    if (f == Failure::kFull) throw JobStoreError("job store: step: database or disk is full", true);
    throw std::runtime_error("something else went wrong");
  }

  JobStore& inner_;
};

class ApiStoreFailure : public ::testing::Test {
 protected:
  void SetUp() override {
    install_api(server_, ctx_);
    port_ = server_.bind_to_any_port("127.0.0.1");
    ASSERT_GT(port_, 0);
    listener_ = std::thread([this] { server_.listen_after_bind(); });
    ASSERT_TRUE(test::eventually([&] { return server_.is_running(); }, 10));
    client_ = std::make_unique<httplib::Client>("127.0.0.1", port_);
    client_->set_read_timeout(20, 0);
  }
  void TearDown() override {
    scheduler_.shutdown();  // its hooks use jobs_
    server_.stop();
    if (listener_.joinable()) listener_.join();
  }

  // A queued job, stored directly (the scheduler is not started: nothing claims it).
  std::string queue_job(int priority = 0) {
    JobRecord job = test::make_job(priority, 1);
    sqlite_.create(job);
    return job.id;
  }

  JobRecord stored(const std::string& id) { return sqlite_.get(id, false).value(); }

  test::TempDir dir_;
  SqliteJobStore sqlite_{dir_.path() / "jobs.db"};
  FlakyStore store_{sqlite_};
  DirectoryJobFiles files_{dir_.path()};
  DirectoryAssetStore assets_{dir_.path()};
  ThreadPool pool_{1};
  Scheduler scheduler_{store_, files_, pool_, SchedulerOptions{}};
  EventHub events_;
  Auth auth_;
  Metrics metrics_;
  JobService jobs_{store_, files_, assets_, scheduler_, events_, metrics_, JobServiceOptions{}};
  // An event stream looks at the store every second (keepalive_s) while nothing happens.
  ApiContext ctx_{jobs_,     assets_, events_, auth_, metrics_,   nullptr, SubmissionLimits{},
                  64u << 20, {},      1,       0,     dir_.path()};
  httplib::Server server_;
  int port_ = 0;
  std::thread listener_;
  std::unique_ptr<httplib::Client> client_;
};

// The problem body of `res`, checked against what every problem of the API has.
json problem_of(const httplib::Result& res, int status) {
  EXPECT_EQ(res->status, status) << res->body;
  EXPECT_EQ(res->get_header_value("Content-Type"), "application/problem+json");
  const json body = json::parse(res->body, nullptr, false);
  EXPECT_TRUE(body.is_object()) << res->body;
  if (!body.is_object()) return json::object();
  EXPECT_EQ(body.value("status", 0), status);
  EXPECT_TRUE(body.contains("type") && body.contains("title") && body.contains("detail")) << body.dump();
  return body;
}

// The problem body of an answer to a failing store: `status`, its Retry-After, and the problem's type and title.
json store_problem_of(const httplib::Result& res, int status, const std::string& retry_after, const std::string& type,
                      const std::string& title) {
  const json p = problem_of(res, status);
  EXPECT_EQ(res->get_header_value("Retry-After"), retry_after);
  EXPECT_EQ(p.value("type", ""), "https://tessera.dev/problems/" + type);
  EXPECT_EQ(p.value("title", ""), title);
  return p;
}

TEST_F(ApiStoreFailure, ReadsAnswer503WithRetryAfter) {
  const std::string id = queue_job();
  store_.failure = FlakyStore::Failure::kLocked;

  for (const std::string& path : {"/v1/jobs/" + id, std::string("/v1/jobs"), "/v1/jobs/" + id + "/preview.png"}) {
    SCOPED_TRACE(path);
    auto res = client_->Get(path.c_str());
    ASSERT_TRUE(res);
    const json p = store_problem_of(res, 503, "5", "unavailable", "Service unavailable");
    EXPECT_NE(p.value("detail", "").find("job store"), std::string::npos) << p.dump();
    EXPECT_NE(p.value("detail", "").find("retried"), std::string::npos) << p.dump();
    // The store's own message stays in the log.
    EXPECT_EQ(p.value("detail", "").find("database is locked"), std::string::npos) << p.dump();
  }
  EXPECT_GE(store_.failures.load(), 3);

  store_.failure = FlakyStore::Failure::kNone;
  auto res = client_->Get(("/v1/jobs/" + id).c_str());
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << res->body;
}

TEST_F(ApiStoreFailure, StateChangesTheStoreRefusesAnswer503AndChangeNothing) {
  const std::string id = queue_job(5);
  store_.failure = FlakyStore::Failure::kLocked;
  store_.writes_only = true;  // the job is found; recording the change fails

  auto res = client_->Post(("/v1/jobs/" + id + "/cancel").c_str());
  ASSERT_TRUE(res);
  problem_of(res, 503);
  EXPECT_EQ(res->get_header_value("Retry-After"), "5");
  EXPECT_EQ(stored(id).state, JobState::kQueued);

  res = client_->Patch(("/v1/jobs/" + id).c_str(), R"({"priority": 9})", "application/json");
  ASSERT_TRUE(res);
  problem_of(res, 503);
  EXPECT_EQ(stored(id).priority, 5);

  // The retry, once the store has recovered, does what the first request would have done.
  store_.failure = FlakyStore::Failure::kNone;
  res = client_->Post(("/v1/jobs/" + id + "/cancel").c_str());
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(stored(id).state, JobState::kCancelled);
}

TEST_F(ApiStoreFailure, AFullStoreAnswers507WithRetryAfterAndChangesNothing) {
  const std::string id = queue_job(5);
  store_.failure = FlakyStore::Failure::kFull;
  store_.writes_only = true;

  struct Call {
    std::string what;
    std::function<httplib::Result()> send;
  };
  const std::vector<Call> calls = {
      {"cancel", [&] { return client_->Post(("/v1/jobs/" + id + "/cancel").c_str()); }},
      {"pause", [&] { return client_->Post(("/v1/jobs/" + id + "/pause").c_str()); }},
      {"priority",
       [&] { return client_->Patch(("/v1/jobs/" + id).c_str(), R"({"priority": 9})", "application/json"); }},
      {"delete", [&] { return client_->Delete(("/v1/jobs/" + id).c_str()); }},
  };
  for (const Call& call : calls) {
    SCOPED_TRACE(call.what);
    auto res = call.send();
    ASSERT_TRUE(res);
    const json p = store_problem_of(res, 507, "30", "insufficient-storage", "Insufficient storage");
    EXPECT_NE(p.value("detail", "").find("nothing was changed"), std::string::npos) << p.dump();
    const JobRecord job = stored(id);
    EXPECT_EQ(job.state, JobState::kQueued);
    EXPECT_EQ(job.priority, 5);
  }

  store_.failure = FlakyStore::Failure::kNone;
  auto res = client_->Delete(("/v1/jobs/" + id).c_str());
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 204) << res->body;
  EXPECT_FALSE(sqlite_.get(id, false));
}

// Once the job is stored, a store that fails to read it back does not turn the answer into a 503: retried without an
// Idempotency-Key, the submission would queue the job twice.
TEST_F(ApiStoreFailure, ASubmissionStoredAndNotReadBackIsAccepted) {
  scheduler_.start();
  store_.failure = FlakyStore::Failure::kLocked;
  store_.reads_only = true;
  auto res = client_->Post("/v1/jobs", test::cornell_job(16, 1).dump(), "application/json");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 202) << res->body;
  const json status = json::parse(res->body, nullptr, false);
  ASSERT_TRUE(status.is_object()) << res->body;
  EXPECT_EQ(res->get_header_value("Location"), "/v1/jobs/" + status.value("id", ""));
  EXPECT_EQ(sqlite_.list(JobFilter{}).size(), 1u);
}

TEST_F(ApiStoreFailure, OtherExceptionsStay500) {
  const std::string id = queue_job();
  store_.failure = FlakyStore::Failure::kOther;
  auto res = client_->Get(("/v1/jobs/" + id).c_str());
  ASSERT_TRUE(res);
  const json p = problem_of(res, 500);
  EXPECT_EQ(p.value("type", ""), "https://tessera.dev/problems/internal-error");
  EXPECT_FALSE(res->has_header("Retry-After"));
}

TEST_F(ApiStoreFailure, AnEventStreamEndsWhenTheStoreFailsAndTheDaemonStaysUp) {
  const std::string id = queue_job();
  std::atomic<bool> got_state{false};
  std::atomic<bool> ended{false};
  std::string received;
  std::thread reader([&] {
    auto res = client_->Get(("/v1/jobs/" + id + "/events").c_str(), [&](const char* data, size_t n) {
      received.append(data, n);
      if (received.find("event: state") != std::string::npos) got_state = true;
      return true;
    });
    ended = true;
  });
  ASSERT_TRUE(test::eventually([&] { return got_state.load(); }, 10));
  // The next keep-alive (a second from now) looks the job up in the store, which fails.
  store_.failure = FlakyStore::Failure::kLocked;
  const bool stream_ended = test::eventually([&] { return ended.load(); }, 10);
  if (!stream_ended) server_.stop();  // unblocks the reader
  reader.join();
  EXPECT_TRUE(stream_ended);

  // The reconnect is told to come back later; once the store recovers, the stream is served again.
  httplib::Client other("127.0.0.1", port_);
  auto res = other.Get(("/v1/jobs/" + id + "/events").c_str());
  ASSERT_TRUE(res);
  problem_of(res, 503);
  EXPECT_EQ(res->get_header_value("Retry-After"), "5");
}

// The value of the unlabelled metric `name` in a /metrics body, or -1 when it is not there.
double metric_value(const std::string& body, const std::string& name) {
  const std::string prefix = "\n" + name + " ";
  const size_t at = body.find(prefix);
  return at == std::string::npos ? -1 : std::stod(body.substr(at + prefix.size()));
}

// Monitoring is what an operator has while the store fails: /metrics still answers, says the store is down, leaves
// out the job counts it cannot know (rather than reporting zero), and counts the failures, the requests' included.
TEST_F(ApiStoreFailure, MetricsAnswerWithoutJobCountsWhileTheStoreFails) {
  const std::string id = queue_job();
  auto res = client_->Get("/metrics");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(metric_value(res->body, "tessera_job_store_up"), 1);
  EXPECT_NE(res->body.find("tessera_jobs{state=\"queued\"} 1\n"), std::string::npos) << res->body;
  EXPECT_EQ(metric_value(res->body, "tessera_queue_length"), 1);
  const double errors = metric_value(res->body, "tessera_job_store_errors_total");
  EXPECT_EQ(errors, 0);

  store_.failure = FlakyStore::Failure::kLocked;
  res = client_->Get(("/v1/jobs/" + id).c_str());
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 503);
  res = client_->Get("/metrics");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(metric_value(res->body, "tessera_job_store_up"), 0);
  EXPECT_EQ(res->body.find("tessera_jobs{"), std::string::npos) << res->body;
  EXPECT_EQ(metric_value(res->body, "tessera_queue_length"), -1);
  EXPECT_EQ(metric_value(res->body, "tessera_job_store_errors_total"), errors + 2);  // the 503 and this scrape
  EXPECT_NE(res->body.find("tessera_http_requests_total{route=\"/v1/jobs/{id}\",code=\"503\"} 1"), std::string::npos)
      << res->body;

  store_.failure = FlakyStore::Failure::kNone;
  res = client_->Get("/metrics");
  ASSERT_TRUE(res);
  EXPECT_EQ(metric_value(res->body, "tessera_job_store_up"), 1);
  EXPECT_EQ(metric_value(res->body, "tessera_queue_length"), 1);
}

// A store that answers reads but refuses a client's change is failing too: /metrics says so (as /readyz does, from
// the same JobService::store_failing) until a change goes through again.
TEST_F(ApiStoreFailure, AStoreThatRefusesOnlyClientWritesIsDown) {
  const std::string id = queue_job(5);
  const auto store_up = [&] {
    auto metrics = client_->Get("/metrics");
    EXPECT_TRUE(metrics);
    return metrics ? metric_value(metrics->body, "tessera_job_store_up") : -1.0;
  };
  EXPECT_EQ(store_up(), 1);
  store_.failure = FlakyStore::Failure::kLocked;
  store_.writes_only = true;
  auto res = client_->Patch(("/v1/jobs/" + id).c_str(), R"({"priority": 9})", "application/json");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 503);
  EXPECT_EQ(store_up(), 0);
  store_.failure = FlakyStore::Failure::kNone;
  res = client_->Patch(("/v1/jobs/" + id).c_str(), R"({"priority": 9})", "application/json");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(store_up(), 1);
}

// /readyz and /metrics say the same of the store: while the end of a render waits for the store to take it (a full
// disk), both say it fails, and the job counts, which can still be read, stay in the scrape.
TEST_F(ApiStoreFailure, ReadyzAndMetricsAgreeWhileAnEndWaitsForTheStore) {
  const auto health = [&] {
    auto ready = client_->Get("/readyz");
    auto metrics = client_->Get("/metrics");
    EXPECT_TRUE(ready && metrics);
    if (!ready || !metrics) return std::pair<int, double>{-1, -1};
    const json storage = json::parse(ready->body)["storage"];
    return std::pair<int, double>{storage.value("job_store_failing", false) ? 1 : 0,
                                  metric_value(metrics->body, "tessera_job_store_up")};
  };
  // Only ends fail: the store reads and takes the job, and both still say it works.
  store_.ends_only = true;
  store_.failure = FlakyStore::Failure::kFull;
  scheduler_.start();
  EXPECT_EQ(health(), (std::pair<int, double>{0, 1}));
  auto checked = check_job_document(test::cornell_job(16, 1), SubmissionLimits{});
  ASSERT_TRUE(std::holds_alternative<Submitted>(
      jobs_.submit(Caller{}, SubmitRequest{std::get<AcceptedJob>(checked), "", "", false})));
  ASSERT_TRUE(test::eventually([&] { return health().first == 1; }, 60));
  EXPECT_EQ(health(), (std::pair<int, double>{1, 0}));
  auto metrics = client_->Get("/metrics");
  EXPECT_NE(metrics->body.find("tessera_jobs{state=\"running\"} 1\n"), std::string::npos) << metrics->body;
  // Recovered: both say so.
  store_.failure = FlakyStore::Failure::kNone;
  EXPECT_TRUE(test::eventually([&] { return health() == std::pair<int, double>{0, 1}; }, 30));
}

// The same API with a store that does not fail: a multipart job whose scene names a file it did not send is told
// which file, where the schema would say only that scene.gltf is not an asset id.
using ApiMultipart = ApiStoreFailure;

TEST_F(ApiMultipart, AJobNamingAFileItDidNotSendIsToldWhichFile) {
  std::ifstream in("examples/box/Box.glb", std::ios::binary);  // tests run from the repository
  const std::string box((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_FALSE(box.empty());
  const json job = {{"kind", "scene"}, {"scene", {{"gltf", "Duck.glb"}}}};
  const std::string expected =
      "scene.gltf names Duck.glb, which this request did not send: add it as a file part, or give an uploaded "
      "asset's id";
  // Another file sent, and none at all.
  for (const httplib::MultipartFormDataItems& items :
       {httplib::MultipartFormDataItems{{"job", job.dump(), "", "application/json"},
                                        {"file", box, "Box.glb", "model/gltf-binary"}},
        httplib::MultipartFormDataItems{{"job", job.dump(), "", "application/json"}}}) {
    const json p = problem_of(client_->Post("/v1/jobs", items), 422);
    EXPECT_EQ(p.value("detail", ""), expected) << p.dump();
    EXPECT_EQ(p.value("pointer", ""), "/scene/gltf");
  }
  // An environment map likewise, by its own field.
  const json sky = {{"kind", "scene"}, {"scene", {{"gltf", "Box.glb"}, {"environment", {{"map", "sky.hdr"}}}}}};
  const json p = problem_of(
      client_->Post("/v1/jobs", httplib::MultipartFormDataItems{{"job", sky.dump(), "", "application/json"},
                                                                {"file", box, "Box.glb", "model/gltf-binary"}}),
      422);
  EXPECT_EQ(p.value("detail", ""),
            "scene.environment.map names sky.hdr, which this request did not send: add it as a file part, or give an "
            "uploaded asset's id");
  EXPECT_EQ(p.value("pointer", ""), "/scene/environment/map");
}

// A medium's grid in a multipart job: the .vdb file part it names becomes a volume asset of its own, and the
// accepted document names it by id; a grid the request did not send is told by its field.
TEST_F(ApiMultipart, AMediumsGridIsAFilePartOrToldWhichFile) {
  ctx_.limits.resolve_asset = asset_resolver(assets_);  // the daemon's (server/main.cpp)
  scheduler_.start();
  const std::filesystem::path vdb = dir_.path() / "smoke.vdb";
  tessera::test::write_vdb(vdb, {tessera::test::make_grid(4, [](int, int, int) { return 1.0f; })});
  std::ifstream in(vdb, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const json box = {{"shape", "sphere"},
                    {"center", {0.1, 0.1, 0.1}},
                    {"radius", 0.2},
                    {"material", "boundary"},
                    {"medium", {{"grid", "smoke.vdb"}, {"sigma_s", 1}}}};
  const json job = {{"kind", "scene"},
                    {"scene",
                     {{"materials", {{"boundary", {{"type", "interface"}}}}},
                      {"objects", {box}},
                      {"camera", {{"from", {0, 0, 2}}, {"to", {0, 0, 0}}}},
                      {"environment", {{"color", 1}}}}},
                    {"render", {{"width", 8}, {"height", 8}, {"spp", 1}}}};
  auto res = client_->Post("/v1/jobs", httplib::MultipartFormDataItems{{"job", job.dump(), "", "application/json"},
                                                                       {"file", bytes, "smoke.vdb", ""}});
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 202) << res->body;
  const std::string id = json::parse(res->body).value("id", "");
  auto document = client_->Get(("/v1/jobs/" + id + "/document").c_str());
  ASSERT_TRUE(document);
  const std::string grid = json::parse(document->body)["scene"]["objects"][0]["medium"]["grid"].get<std::string>();
  ASSERT_TRUE(is_asset_id(grid)) << document->body;
  EXPECT_EQ(assets_.get(grid)->kind, "volume");
  const json p = problem_of(
      client_->Post("/v1/jobs", httplib::MultipartFormDataItems{{"job", job.dump(), "", "application/json"}}), 422);
  EXPECT_EQ(p.value("pointer", ""), "/scene/objects/0/medium/grid") << p.dump();
  EXPECT_EQ(p.value("detail", ""),
            "scene.objects.0.medium.grid names smoke.vdb, which this request did not send: add it as a file part, or "
            "give an uploaded asset's id");
}

}  // namespace
}  // namespace tessera::server
