// The SQLite job store's prepared-statement cache (server/store/sqlite_job_store.cpp: each SQL text prepared once,
// reset and unbound after every use, finalized before the connection closes), through the store's public API only. A
// raw second connection to the same file looks at what the store's connection holds: a statement left unreset keeps a
// read transaction open (a TRUNCATE checkpoint cannot finish), a statement left unfinalized keeps the connection open
// after the store is destroyed (the WAL file stays, and the database cannot leave WAL mode).
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "server/base/job_id.h"
#include "server/store/sqlite_job_store.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

namespace fs = std::filesystem;

// test::make_job with an owner, a document that tells jobs apart, and optionally an idempotency key.
JobRecord make_job(const std::string& owner, int priority, int64_t created_at_ms, const std::string& key = "") {
  JobRecord r = test::make_job(priority, created_at_ms);
  r.document = R"({"kind":"scene","n":)" + std::to_string(created_at_ms) + "}";
  r.owner = owner;
  r.idempotency_key = key;
  r.request_hash = key.empty() ? "" : "hash-" + key;
  return r;
}

// A connection of its own to the store's file, with no busy timeout: anything the store's connection still holds
// shows up at once as SQLITE_BUSY instead of a wait.
class RawConnection {
 public:
  explicit RawConnection(const fs::path& file) {
    if (sqlite3_open_v2(file.c_str(), &db_, SQLITE_OPEN_READWRITE, nullptr) != SQLITE_OK) {
      ADD_FAILURE() << "cannot open " << file << ": " << sqlite3_errmsg(db_);
    }
  }
  ~RawConnection() { EXPECT_EQ(sqlite3_close(db_), SQLITE_OK); }
  RawConnection(const RawConnection&) = delete;
  RawConnection& operator=(const RawConnection&) = delete;

  // The first column of the first row of `sql`, as text; "rc=N" when the statement fails.
  std::string scalar(const std::string& sql) {
    sqlite3_stmt* stmt = nullptr;
    int rc = sqlite3_prepare_v2(db_, sql.c_str(), -1, &stmt, nullptr);
    if (rc != SQLITE_OK) return "rc=" + std::to_string(rc);
    std::string out;
    rc = sqlite3_step(stmt);
    if (rc == SQLITE_ROW) {
      const unsigned char* p = sqlite3_column_text(stmt, 0);
      out = p ? reinterpret_cast<const char*>(p) : "NULL";
    } else if (rc != SQLITE_DONE) {
      out = "rc=" + std::to_string(rc);
    }
    sqlite3_finalize(stmt);
    return out;
  }

  // Runs a TRUNCATE checkpoint: it must wait for every reader of the WAL, so it completes (busy = 0, the WAL emptied)
  // only when the store's connection holds no read transaction.
  ::testing::AssertionResult checkpoint_truncates() {
    // A connection learns the database is in WAL mode on its first read; before that a checkpoint does nothing.
    if (scalar("SELECT COUNT(*) FROM jobs").starts_with("rc=")) return ::testing::AssertionFailure() << "cannot read";
    if (scalar("PRAGMA journal_mode") != "wal") return ::testing::AssertionFailure() << "not in WAL mode";
    int log_frames = -1, checkpointed = -1;
    int rc = sqlite3_wal_checkpoint_v2(db_, nullptr, SQLITE_CHECKPOINT_TRUNCATE, &log_frames, &checkpointed);
    if (rc != SQLITE_OK) {
      return ::testing::AssertionFailure() << "TRUNCATE checkpoint: rc=" << rc << " (" << sqlite3_errmsg(db_)
                                           << "): another connection still reads the WAL (a statement was not reset)";
    }
    if (log_frames != 0) return ::testing::AssertionFailure() << "the WAL still has " << log_frames << " frames";
    return ::testing::AssertionSuccess();
  }

 private:
  sqlite3* db_ = nullptr;
};

JobProgress progress_of_pass(uint32_t pass) {
  JobProgress p;
  p.passes = pass;
  p.samples_done = 2 * pass;
  p.samples_total = 1000;
  p.elapsed_s = 0.5 * pass;
  if (pass % 2 == 1) p.eta_s = 100.0 - pass;  // a value on odd passes, NULL on even ones: both through one statement
  p.samples_per_s = 10.0 * pass;
  return p;
}

// The same statements run many times, each after a write: every read returns the row as it is now, never a row (or
// a column) of an earlier run.
TEST(SqliteJobStoreStatementCache, RepeatedQueriesSeeEveryWrite) {
  test::TempDir dir;
  SqliteJobStore store(dir.path() / "jobs.db");
  JobRecord job = make_job("alice", 0, 1);
  store.create(job);
  ASSERT_EQ(store.claim_next(5)->id, job.id);

  for (uint32_t pass = 1; pass <= 200; ++pass) {
    SCOPED_TRACE("pass " + std::to_string(pass));
    const JobProgress p = progress_of_pass(pass);
    store.update_progress(job.id, 1, p);
    ASSERT_TRUE(store.set_priority(job.id, static_cast<int>(pass)));
    const bool with_document = pass % 3 == 0;  // two SQL texts of get(), interleaved
    auto got = store.get(job.id, with_document);
    ASSERT_TRUE(got);
    EXPECT_EQ(got->id, job.id);
    EXPECT_EQ(got->state, JobState::kRunning);
    EXPECT_EQ(got->priority, static_cast<int>(pass));
    EXPECT_EQ(got->progress.passes, pass);
    EXPECT_EQ(got->progress.samples_done, 2 * pass);
    EXPECT_DOUBLE_EQ(got->progress.elapsed_s, 0.5 * pass);
    EXPECT_EQ(got->progress.eta_s, p.eta_s);
    EXPECT_DOUBLE_EQ(got->progress.samples_per_s, 10.0 * pass);
    EXPECT_EQ(got->document, with_document ? job.document : "");
    auto counts = store.count_by_state(std::nullopt);
    EXPECT_EQ(counts[JobState::kRunning], 1);
    EXPECT_EQ(counts[JobState::kQueued], 0);
  }

  // Pause, resume, claim again, finish: the same get() after each step sees the new state.
  ASSERT_TRUE(store.transition(job.id, JobState::kPaused, 300, "", ""));
  EXPECT_EQ(store.get(job.id, false)->state, JobState::kPaused);
  EXPECT_FALSE(store.get(job.id, false)->progress.eta_s);  // pausing clears the estimate
  ASSERT_TRUE(store.transition(job.id, JobState::kQueued, 301, "", ""));
  EXPECT_EQ(store.get(job.id, false)->state, JobState::kQueued);
  EXPECT_EQ(store.get(job.id, false)->progress.passes, 0u);
  EXPECT_EQ(store.queue_position(job.id), 1);
  ASSERT_EQ(store.claim_next(302)->id, job.id);
  EXPECT_FALSE(store.queue_position(job.id));
  ASSERT_TRUE(store.transition(job.id, JobState::kSucceeded, 303, "samples", ""));
  auto done = store.get(job.id, false);
  EXPECT_EQ(done->state, JobState::kSucceeded);
  EXPECT_EQ(done->finished_at_ms, 303);
  EXPECT_EQ(done->stop_reason, "samples");
  EXPECT_FALSE(store.set_priority(job.id, 7));  // an ended job keeps its priority
  EXPECT_EQ(store.get(job.id, false)->priority, 200);
}

// One SQL text with other parameters each time: each call answers for its own parameters, including a run that finds
// nothing right after one that found a row.
TEST(SqliteJobStoreStatementCache, EachUseAnswersForItsOwnParameters) {
  test::TempDir dir;
  SqliteJobStore store(dir.path() / "jobs.db");
  std::vector<JobRecord> jobs;
  for (int i = 0; i < 20; ++i) {
    jobs.push_back(make_job("owner" + std::to_string(i % 4), i % 3, i, "key" + std::to_string(i)));
    store.create(jobs.back());
  }
  // Claim order: priority 2 (i = 2, 5, ...), then 1, then 0; by submission within one priority.
  std::vector<std::string> claim_order;
  for (int prio = 2; prio >= 0; --prio)
    for (const JobRecord& j : jobs)
      if (j.priority == prio) claim_order.push_back(j.id);

  for (int round = 0; round < 3; ++round) {
    for (size_t k = 0; k < jobs.size(); ++k) {
      // Walk the jobs in another order each round, so a cached statement never sees the same parameters twice in a
      // row.
      const JobRecord& j = jobs[(k * 7 + static_cast<size_t>(round) * 3) % jobs.size()];
      SCOPED_TRACE("round " + std::to_string(round) + ", job " + j.idempotency_key);
      auto got = store.get(j.id, false);
      ASSERT_TRUE(got);
      EXPECT_EQ(got->id, j.id);
      EXPECT_EQ(got->owner, j.owner);
      EXPECT_EQ(got->created_at_ms, j.created_at_ms);
      EXPECT_EQ(got->idempotency_key, j.idempotency_key);
      EXPECT_EQ(got->request_hash, j.request_hash);
      EXPECT_FALSE(store.get(new_job_id(), false));  // an unknown id, right after a hit

      auto by_key = store.find_by_idempotency_key(j.owner, j.idempotency_key);
      ASSERT_TRUE(by_key);
      EXPECT_EQ(by_key->id, j.id);
      EXPECT_FALSE(store.find_by_idempotency_key(j.owner == "owner0" ? "owner1" : "owner0", j.idempotency_key));

      const auto pos = std::find(claim_order.begin(), claim_order.end(), j.id) - claim_order.begin() + 1;
      EXPECT_EQ(store.queue_position(j.id), static_cast<int>(pos));

      EXPECT_EQ(store.count_by_state(j.owner)[JobState::kQueued], 5);
      JobFilter mine;
      mine.owner = j.owner;
      mine.before_seq = got->seq + 1;
      mine.limit = 1;
      auto listed = store.list(mine);
      ASSERT_EQ(listed.size(), 1u);
      EXPECT_EQ(listed[0].id, j.id);  // the newest of this owner's jobs up to and including j
    }
  }
  EXPECT_EQ(store.count_by_state(std::nullopt)[JobState::kQueued], 20);
  EXPECT_FALSE(store.count_by_state(std::string("nobody")).at(JobState::kQueued));
}

// get(), find_by_idempotency_key() and queue_position() return after the first row: their statement is left with a
// row pending. Handing it back must end that read: the next use (same text, other parameters) starts afresh, writes
// in between are seen, and no read transaction stays open to hold back another connection's checkpoint.
TEST(SqliteJobStoreStatementCache, ReadLeftMidIterationDoesNotLeakIntoTheNextUse) {
  test::TempDir dir;
  const fs::path file = dir.path() / "jobs.db";
  SqliteJobStore store(file);
  JobRecord a = make_job("alice", 0, 1, "ka"), b = make_job("alice", 0, 2, "kb"), c = make_job("bob", 0, 3, "kc");
  for (const JobRecord* j : {&a, &b, &c}) store.create(*j);

  // Before each read that stops after its first row, a write: the WAL has frames, so the read (while it lasts)
  // holds a snapshot in the WAL, which a TRUNCATE checkpoint must wait for.
  int writes = 0;
  auto write = [&] { store.set_warnings(a.id, "[\"" + std::to_string(++writes) + "\"]"); };
  for (int round = 0; round < 25; ++round) {
    SCOPED_TRACE("round " + std::to_string(round));
    write();
    ASSERT_EQ(store.get(a.id, round % 2 == 0)->id, a.id);
    {
      RawConnection other(file);
      EXPECT_TRUE(other.checkpoint_truncates()) << "after get()";
    }
    auto got_b = store.get(b.id, round % 2 == 0);  // same text, another id
    ASSERT_TRUE(got_b);
    EXPECT_EQ(got_b->id, b.id);
    EXPECT_EQ(store.get(a.id, false)->warnings, "[\"" + std::to_string(writes) + "\"]");

    write();
    ASSERT_EQ(store.find_by_idempotency_key("alice", "kb")->id, b.id);
    {
      RawConnection other(file);
      EXPECT_TRUE(other.checkpoint_truncates()) << "after find_by_idempotency_key()";
    }
    ASSERT_EQ(store.find_by_idempotency_key("bob", "kc")->id, c.id);

    write();
    ASSERT_EQ(store.queue_position(c.id), 3);
    {
      RawConnection other(file);
      EXPECT_TRUE(other.checkpoint_truncates()) << "after queue_position()";
    }
    // A write after the half-read statements: it commits (another connection sees it) and the reads see it.
    ASSERT_TRUE(store.set_priority(c.id, round + 1));
    {
      RawConnection other(file);
      EXPECT_EQ(other.scalar("SELECT priority FROM jobs WHERE id = '" + c.id + "'"), std::to_string(round + 1));
    }
    EXPECT_EQ(store.queue_position(c.id), 1);  // now the highest priority
    EXPECT_EQ(store.queue_position(a.id), 2);
    EXPECT_EQ(store.get(c.id, false)->priority, round + 1);
    ASSERT_TRUE(store.set_priority(c.id, 0));
  }

  // A job removed while the statements that read it are cached: the same reads now find nothing.
  ASSERT_TRUE(store.get(b.id, false));
  ASSERT_TRUE(store.remove(b.id));
  EXPECT_FALSE(store.get(b.id, false));
  EXPECT_FALSE(store.find_by_idempotency_key("alice", "kb"));
  EXPECT_FALSE(store.queue_position(b.id));
  EXPECT_EQ(store.queue_position(c.id), 2);
}

// A statement whose step failed (a duplicate id) is handed back reset: the next insert through it works.
TEST(SqliteJobStoreStatementCache, FailedStepLeavesTheStatementReusable) {
  test::TempDir dir;
  SqliteJobStore store(dir.path() / "jobs.db");
  std::vector<JobRecord> created;
  for (int i = 0; i < 10; ++i) {
    JobRecord j = make_job("alice", 0, i, "key" + std::to_string(i));
    store.create(j);
    created.push_back(j);
    EXPECT_THROW(store.create(j), std::runtime_error);  // same id
    JobRecord same_key = make_job("alice", 0, 100 + i, j.idempotency_key);
    EXPECT_THROW(store.create(same_key), std::runtime_error);  // same owner and Idempotency-Key
  }
  auto all = store.list({});
  ASSERT_EQ(all.size(), created.size());
  for (size_t i = 0; i < created.size(); ++i) {
    EXPECT_EQ(all[created.size() - 1 - i].id, created[i].id);
    EXPECT_EQ(all[created.size() - 1 - i].created_at_ms, created[i].created_at_ms);
  }
}

// list() builds its SQL from the filter, so a caller can make more distinct texts than the cache keeps (256): past
// that, statements are prepared for one use and finalized. Answers stay right on both sides of the limit, the cached
// statements keep working, and the store still closes cleanly.
TEST(SqliteJobStoreStatementCache, MoreTextsThanTheCacheKeepsStayCorrect) {
  test::TempDir dir;
  const fs::path file = dir.path() / "jobs.db";
  // Submitted in this order; `running` has the higher priority, so it is the one claimed.
  JobRecord queued = make_job("", 0, 1), running = make_job("", 1, 2), cancelled = make_job("", 0, 3);
  {
    SqliteJobStore store(file);
    for (const JobRecord* j : {&queued, &running, &cancelled}) store.create(*j);
    ASSERT_EQ(store.claim_next(10)->id, running.id);
    ASSERT_TRUE(store.transition(cancelled.id, JobState::kCancelled, 11, "cancelled", ""));

    for (int n = 1; n <= 400; ++n) {
      SCOPED_TRACE("filter of " + std::to_string(n) + " states");
      // n states, cycling through queued, running, cancelled: a distinct SQL text for every n.
      JobFilter f;
      const JobState cycle[] = {JobState::kQueued, JobState::kRunning, JobState::kCancelled};
      for (int k = 0; k < n; ++k) f.states.push_back(cycle[k % 3]);
      auto got = store.list(f);
      std::vector<std::string> ids;
      for (const JobRecord& r : got) ids.push_back(r.id);
      if (n == 1)
        EXPECT_EQ(ids, std::vector<std::string>{queued.id});
      else if (n == 2)
        EXPECT_EQ(ids, (std::vector<std::string>{running.id, queued.id}));
      else
        EXPECT_EQ(ids, (std::vector<std::string>{cancelled.id, running.id, queued.id}));
      // A cached text between the uncached ones still answers for its parameters.
      EXPECT_EQ(store.get(n % 2 ? running.id : cancelled.id, false)->state,
                n % 2 ? JobState::kRunning : JobState::kCancelled);
    }
    // The first texts, cached long ago, after hundreds of others.
    JobFilter only_queued;
    only_queued.states = {JobState::kQueued};
    ASSERT_EQ(store.list(only_queued).size(), 1u);
    EXPECT_EQ(store.queue_position(queued.id), 1);
    store.update_progress(running.id, 1, progress_of_pass(3));
    EXPECT_EQ(store.get(running.id, false)->progress.passes, 3u);
  }
  // Closed cleanly: no connection left behind (see ClosingWithCachedStatementsReleasesTheDatabase).
  EXPECT_FALSE(fs::exists(fs::path(file.string() + "-wal")));
  SqliteJobStore reopened(file);
  EXPECT_EQ(reopened.get(running.id, false)->progress.passes, 3u);
}

// Destroying the store finalizes every cached statement, including one a read left with a row pending, so the
// connection really closes: SQLite checkpoints and deletes the WAL file on the last close, and only then can another
// connection take the database out of WAL mode (it needs the database to itself). A connection left open because
// sqlite3_close() met an unfinalized statement (SQLITE_BUSY) fails both, and leaks (LeakSanitizer, under ASan).
TEST(SqliteJobStoreStatementCache, ClosingWithCachedStatementsReleasesTheDatabase) {
  test::TempDir dir;
  const fs::path file = dir.path() / "jobs.db";
  const fs::path wal = file.string() + "-wal";
  JobRecord a = make_job("alice", 1, 1, "ka"), b = make_job("bob", 0, 2);
  for (int reopen = 0; reopen < 3; ++reopen) {
    SCOPED_TRACE("store " + std::to_string(reopen));
    {
      SqliteJobStore store(file);
      if (reopen == 0) {
        store.create(a);
        store.create(b);
      }
      // Every public method, so every kind of statement is in the cache at the end.
      ASSERT_TRUE(store.get(a.id, true));
      ASSERT_TRUE(store.list({}).size() == 2);
      store.count_by_state(std::nullopt);
      store.count_by_state(std::string("alice"));
      store.set_warnings(b.id, R"(["w)" + std::to_string(reopen) + R"("])");
      if (reopen == 0) {
        ASSERT_EQ(store.claim_next(5)->id, a.id);
        store.update_progress(a.id, 1, progress_of_pass(4));
        ASSERT_TRUE(store.transition(a.id, JobState::kPaused, 6, "", ""));
      } else {
        EXPECT_EQ(store.requeue_running(), 0);
      }
      EXPECT_TRUE(fs::exists(wal));  // WAL mode, with the connection open
      // The last thing before the destructor: reads that stop after their first row.
      ASSERT_TRUE(store.find_by_idempotency_key("alice", "ka"));
      ASSERT_EQ(store.queue_position(b.id), 1);
      ASSERT_TRUE(store.get(b.id, false));
    }
    EXPECT_FALSE(fs::exists(wal)) << "the store's connection is still open after its destructor";
    {
      RawConnection other(file);
      EXPECT_EQ(other.scalar("SELECT warnings FROM jobs WHERE id = '" + b.id + "'"),
                R"(["w)" + std::to_string(reopen) + R"("])");
      EXPECT_EQ(other.scalar("PRAGMA journal_mode=DELETE"), "delete") << "another connection holds the database";
      EXPECT_EQ(other.scalar("PRAGMA journal_mode=WAL"), "wal");
    }
  }
  SqliteJobStore store(file);  // and it opens again, with what the first store wrote
  auto got = store.get(a.id, false);
  ASSERT_TRUE(got);
  EXPECT_EQ(got->state, JobState::kPaused);
  EXPECT_EQ(got->progress.passes, 4u);
}

}  // namespace
}  // namespace tessera::server
