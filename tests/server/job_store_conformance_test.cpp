// What every JobStore does, whatever keeps the jobs: one typed suite run against the SQLite store (a file in a
// temporary directory) and the PostgreSQL store (a fresh database in a throw-away server, postgres_cluster.h). Claim
// order (priority, then first come), every move of the state table and no other, a refused move that writes nothing,
// concurrent claims, leases (renewal, expiry, take-over) and fencing by epoch, progress, lists, removal, idempotency
// keys, counts per owner, a restart.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <thread>

#include "server/store/job_state.h"
#include "server/store/postgres_job_store.h"
#include "server/store/sqlite_job_store.h"
#include "tests/server/postgres_cluster.h"
#include "tests/server/test_util.h"

namespace tessera::server {
namespace {

using test::make_job;

struct SqliteBackend {
  test::TempDir dir;
  // Every store opened on one backend shares its jobs (a second daemon, or the same one restarted).
  std::unique_ptr<JobStore> open(const std::string& /*node*/ = "node-a") {
    return std::make_unique<SqliteJobStore>(dir.path() / "jobs.db");
  }
};

struct PostgresBackend {
  std::string uri = test::PostgresCluster::shared().create_database();
  std::unique_ptr<JobStore> open(const std::string& node = "node-a") {
    return std::make_unique<PostgresJobStore>(uri, node);
  }
};

template <typename Backend>
class JobStoreConformance : public ::testing::Test {
 protected:
  Backend backend;
  std::unique_ptr<JobStore> owned = backend.open();
  JobStore& store = *owned;

  // A new job of `owner`, driven into `state` (which claims it when it must run: nothing else may be queued).
  JobRecord job_in(JobState state, const std::string& owner = "") {
    JobRecord j = make_job(0, 1);
    j.owner = owner;
    store.create(j);
    switch (state) {
      case JobState::kQueued:
        break;
      case JobState::kPaused:
        EXPECT_TRUE(store.transition(j.id, JobState::kPaused, 2));
        break;
      case JobState::kRunning:
      case JobState::kSucceeded:
      case JobState::kFailed:
      case JobState::kCancelled: {
        auto claimed = store.claim_next(2);
        EXPECT_TRUE(claimed && claimed->id == j.id);
        if (claimed) j.epoch = claimed->epoch;
        if (state != JobState::kRunning) {
          EXPECT_TRUE(store.transition(j.id, state, 3, "samples", ""));
        }
        break;
      }
    }
    EXPECT_EQ(store.get(j.id, false)->state, state);
    return j;
  }
};

using Backends = ::testing::Types<SqliteBackend, PostgresBackend>;
class BackendNames {
 public:
  template <typename T>
  static std::string GetName(int) {
    return std::is_same_v<T, SqliteBackend> ? "Sqlite" : "Postgres";
  }
};
TYPED_TEST_SUITE(JobStoreConformance, Backends, BackendNames);

TYPED_TEST(JobStoreConformance, ClaimsByPriorityThenFirstCome) {
  JobStore& store = this->store;
  JobRecord a = make_job(0, 1), b = make_job(5, 2), c = make_job(0, 3), d = make_job(5, 4);
  for (const JobRecord* j : {&a, &b, &c, &d}) store.create(*j);
  std::vector<std::string> order;
  while (auto j = store.claim_next(100)) {
    EXPECT_EQ(j->state, JobState::kRunning);
    EXPECT_EQ(j->started_at_ms, 100);
    EXPECT_EQ(j->document, R"({"kind":"scene"})");  // a claim brings the document to render
    order.push_back(j->id);
  }
  EXPECT_EQ(order, (std::vector<std::string>{b.id, d.id, a.id, c.id}));
}

// Every (from, to) pair: the store makes exactly the moves can_transition() allows, and a refused one changes nothing.
TYPED_TEST(JobStoreConformance, MakesEveryMoveTheStateTableAllowsAndNoOther) {
  JobStore& store = this->store;
  for (JobState from : kAllJobStates) {
    for (JobState to : kAllJobStates) {
      SCOPED_TRACE(std::string(job_state_name(from)) + " -> " + job_state_name(to));
      const JobRecord j = this->job_in(from);
      const bool allowed = can_transition(from, to);
      EXPECT_EQ(store.transition(j.id, to, 50, "reason", ""), allowed);
      EXPECT_EQ(store.get(j.id, false)->state, allowed ? to : from);
      store.remove(j.id);
      // Only from a named state: refused from any other.
      for (JobState only : kAllJobStates) {
        if (only == from || !allowed) continue;
        const JobRecord k = this->job_in(from);
        EXPECT_FALSE(store.transition(k.id, to, 50, "", "", only)) << "only from " << job_state_name(only);
        EXPECT_EQ(store.get(k.id, false)->state, from);
        store.remove(k.id);
      }
    }
  }
  EXPECT_FALSE(store.transition(new_job_id(), JobState::kCancelled, 1, "", ""));  // unknown id
}

// A node that finished a render whose job was cancelled meanwhile (through another node, or another request) must
// not write its end over the cancellation.
TYPED_TEST(JobStoreConformance, AnEndRefusedAfterACancelWritesNothing) {
  JobStore& store = this->store;
  const JobRecord j = this->job_in(JobState::kRunning);
  ASSERT_TRUE(store.transition(j.id, JobState::kCancelled, 10, "cancelled", ""));
  EXPECT_FALSE(store.transition(j.id, JobState::kSucceeded, 20, "samples", ""));
  EXPECT_FALSE(store.transition(j.id, JobState::kFailed, 20, "", "boom"));
  EXPECT_FALSE(store.transition(j.id, JobState::kPaused, 20));
  const auto got = store.get(j.id, false);
  EXPECT_EQ(got->state, JobState::kCancelled);
  EXPECT_EQ(got->stop_reason, "cancelled");
  EXPECT_EQ(got->finished_at_ms, 10);
  EXPECT_EQ(got->error, "");
}

TYPED_TEST(JobStoreConformance, AnEndIsStampedAndARequeueStartsOver) {
  JobStore& store = this->store;
  const JobRecord j = this->job_in(JobState::kRunning);
  JobProgress p;
  p.passes = 3;
  p.samples_done = 7;
  p.samples_total = 16;
  p.elapsed_s = 0.1;  // not a binary fraction: read back exactly all the same
  p.eta_s = 2.5e-7;
  p.samples_per_s = 1234.5678;
  EXPECT_TRUE(store.update_progress(j.id, j.epoch, p));
  auto got = store.get(j.id, false);
  EXPECT_EQ(got->progress.passes, 3u);
  EXPECT_EQ(got->progress.samples_done, 7u);
  EXPECT_EQ(got->progress.elapsed_s, 0.1);
  EXPECT_EQ(got->progress.eta_s, 2.5e-7);
  EXPECT_EQ(got->progress.samples_per_s, 1234.5678);
  EXPECT_TRUE(got->document.empty());  // not asked for
  EXPECT_TRUE(store.transition(j.id, JobState::kFailed, 9, "", "out of memory"));
  got = store.get(j.id, true);
  EXPECT_EQ(got->finished_at_ms, 9);
  EXPECT_EQ(got->error, "out of memory");
  EXPECT_EQ(got->document, R"({"kind":"scene"})");
  EXPECT_FALSE(store.update_progress(j.id, j.epoch, JobProgress{}));  // only a running job's progress is written
  EXPECT_EQ(store.get(j.id, false)->progress.samples_done, 7u);

  EXPECT_TRUE(store.transition(j.id, JobState::kQueued, 10));
  got = store.get(j.id, false);
  EXPECT_EQ(got->state, JobState::kQueued);
  EXPECT_FALSE(got->started_at_ms);
  EXPECT_FALSE(got->finished_at_ms);
  EXPECT_EQ(got->error, "");
  EXPECT_EQ(got->stop_reason, "");
  EXPECT_EQ(got->progress.samples_done, 0u);
  EXPECT_EQ(got->progress.samples_total, 16u);
  EXPECT_EQ(store.queue_position(j.id), 1);
}

TYPED_TEST(JobStoreConformance, ASucceededJobKeepsItsStopReasonAndAZeroEta) {
  JobStore& store = this->store;
  const JobRecord j = this->job_in(JobState::kRunning);
  JobProgress p;
  p.eta_s = 3;
  ASSERT_TRUE(store.update_progress(j.id, j.epoch, p));
  ASSERT_TRUE(store.end_run(j.id, j.epoch, JobState::kSucceeded, 9, "time", ""));
  const auto got = store.get(j.id, false);
  EXPECT_EQ(got->stop_reason, "time");
  EXPECT_EQ(got->progress.eta_s, 0.0);
  EXPECT_EQ(got->finished_at_ms, 9);
}

// Two daemons (two connections) claiming at once from one queue: every job is claimed exactly once.
TYPED_TEST(JobStoreConformance, ConcurrentClaimsTakeEachJobOnce) {
  constexpr int kJobs = 60;
  std::set<std::string> ids;
  for (int i = 0; i < kJobs; ++i) {
    JobRecord j = make_job(i % 3, i);
    this->store.create(j);
    ids.insert(j.id);
  }
  std::unique_ptr<JobStore> other = this->backend.open("node-b");
  std::mutex mutex;
  std::vector<std::string> claimed;
  auto claimer = [&](JobStore& s) {
    while (auto j = s.claim_next(5)) {
      std::lock_guard lock(mutex);
      claimed.push_back(j->id);
    }
  };
  std::thread a([&] { claimer(this->store); });
  std::thread b([&] { claimer(*other); });
  a.join();
  b.join();
  EXPECT_EQ(claimed.size(), static_cast<size_t>(kJobs));
  EXPECT_EQ(std::set<std::string>(claimed.begin(), claimed.end()), ids);
}

// With a cap on the runs an owner holds, a claim passes over the owner at the cap for the next one's jobs, and takes
// the owner's again once a run ends or its lease runs out (a run under an expired lease holds nothing); 0 is no cap.
TYPED_TEST(JobStoreConformance, AnOwnerAtTheRunningCapIsPassedOverUntilARunEnds) {
  JobStore& store = this->store;
  JobRecord a1 = make_job(0, 1), a2 = make_job(0, 2), b1 = make_job(0, 3);
  a1.owner = a2.owner = "alice";
  b1.owner = "bob";
  for (const JobRecord* j : {&a1, &a2, &b1}) store.create(*j);
  const auto first = store.claim_next(10, 1000, 1);
  ASSERT_TRUE(first);
  EXPECT_EQ(first->id, a1.id);
  EXPECT_EQ(store.claim_next(10, 100'000, 1)->id, b1.id);  // alice holds her one: bob's job, submitted after hers
  EXPECT_FALSE(store.claim_next(10, 1000, 1));             // both at their cap
  EXPECT_TRUE(store.end_run(a1.id, first->epoch, JobState::kSucceeded, 20));
  const auto second = store.claim_next(30, 1000, 1);
  ASSERT_TRUE(second);
  EXPECT_EQ(second->id, a2.id);
  // Past its lease (a node that died), a run holds nothing: its own job is claimed again under the cap.
  const auto again = store.claim_next(1031, 1000, 1);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->id, a2.id);
  EXPECT_GT(again->epoch, second->epoch);
  // No cap: alice's next job is claimed beside her running one.
  JobRecord a3 = make_job(0, 4);
  a3.owner = "alice";
  store.create(a3);
  EXPECT_FALSE(store.claim_next(1040, 1000, 1));
  EXPECT_EQ(store.claim_next(1040, 1000, 0)->id, a3.id);
}

// Nodes claiming at once never give an owner more runs than the cap: two stores (two daemons) claim in two threads
// until nothing is left, twenty times over, with two owners of twelve jobs each under a cap of 2.
TYPED_TEST(JobStoreConformance, ConcurrentClaimsNeverPassAnOwnersCap) {
  std::unique_ptr<JobStore> other = this->backend.open("node-b");
  for (int round = 0; round < 20; ++round) {
    const int64_t now = 1000 * (round + 1);
    for (int i = 0; i < 24; ++i) {
      JobRecord j = make_job(0, now + i);
      j.owner = i % 2 ? "alice" : "bob";
      this->store.create(j);
    }
    std::mutex mutex;
    std::map<std::string, int> runs;  // by owner
    std::vector<std::string> claimed;
    auto claimer = [&](JobStore& s) {
      while (auto j = s.claim_next(now, 100'000'000, 2)) {
        std::lock_guard lock(mutex);
        ++runs[j->owner];
        claimed.push_back(j->id);
      }
    };
    std::thread a([&] { claimer(this->store); });
    std::thread b([&] { claimer(*other); });
    a.join();
    b.join();
    EXPECT_EQ(runs["alice"], 2) << "round " << round;
    EXPECT_EQ(runs["bob"], 2) << "round " << round;
    // The runs end (and every other job is cancelled), so the next round starts with none under way.
    for (const std::string& id : claimed)
      EXPECT_TRUE(this->store.transition(id, JobState::kCancelled, now + 500, "cancelled", ""));
    JobFilter queued;
    queued.state = JobState::kQueued;
    queued.limit = 1000;
    for (const JobRecord& j : this->store.list(queued))
      EXPECT_TRUE(this->store.transition(j.id, JobState::kCancelled, now + 500, "cancelled", ""));
  }
}

TYPED_TEST(JobStoreConformance, QueuePositionFollowsPriorityAndPriorityChangesOnlyWhileNotEnded) {
  JobStore& store = this->store;
  JobRecord a = make_job(0, 1), b = make_job(0, 2), c = make_job(0, 3);
  for (const JobRecord* j : {&a, &b, &c}) store.create(*j);
  EXPECT_EQ(store.queue_position(a.id), 1);
  EXPECT_EQ(store.queue_position(c.id), 3);
  EXPECT_TRUE(store.set_priority(c.id, 10));
  EXPECT_EQ(store.queue_position(c.id), 1);
  EXPECT_EQ(store.queue_position(a.id), 2);
  EXPECT_EQ(store.claim_next(5)->id, c.id);
  EXPECT_FALSE(store.queue_position(c.id));  // not queued
  EXPECT_EQ(store.set_priority(c.id, 3), action_allowed(JobAction::kPriority, JobState::kRunning));
  ASSERT_TRUE(store.transition(c.id, JobState::kSucceeded, 6, "samples", ""));
  EXPECT_FALSE(store.set_priority(c.id, 7));  // ended
  EXPECT_FALSE(store.set_priority(new_job_id(), 7));
}

TYPED_TEST(JobStoreConformance, ListsNewestFirstWithFiltersAndACursor) {
  JobStore& store = this->store;
  std::vector<JobRecord> jobs;
  for (int i = 0; i < 5; ++i) {
    jobs.push_back(make_job(i % 2, i));
    jobs.back().owner = i < 3 ? "ann" : "bob";
    store.create(jobs.back());
  }
  store.claim_next(10);  // jobs[1] (priority 1, first)
  auto all = store.list({});
  ASSERT_EQ(all.size(), 5u);
  EXPECT_EQ(all.front().id, jobs[4].id);
  EXPECT_EQ(all.back().id, jobs[0].id);
  JobFilter running;
  running.state = JobState::kRunning;
  auto r = store.list(running);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].id, jobs[1].id);
  JobFilter two;
  two.limit = 2;
  EXPECT_EQ(store.list(two).size(), 2u);
  JobFilter ann;
  ann.owner = "ann";
  ann.states = {JobState::kQueued};
  ann.before_seq = all[2].seq;  // jobs[2]: only those before it
  auto older = store.list(ann);
  ASSERT_EQ(older.size(), 1u);
  EXPECT_EQ(older[0].id, jobs[0].id);
}

TYPED_TEST(JobStoreConformance, ListsByFinishTimeAndRemovesOnlyAJobStillEndedBeforeTheCutoff) {
  JobStore& store = this->store;
  const JobRecord queued = this->job_in(JobState::kQueued);
  EXPECT_FALSE(store.remove(queued.id, 1000000));
  const JobRecord failed = make_job(0, 1);
  store.create(failed);
  ASSERT_TRUE(store.transition(failed.id, JobState::kCancelled, 500, "cancelled", ""));
  JobFilter filter;
  filter.finished_before_ms = 501;
  ASSERT_EQ(store.list(filter).size(), 1u);
  filter.finished_before_ms = 500;
  EXPECT_TRUE(store.list(filter).empty());
  EXPECT_FALSE(store.remove(failed.id, 500));  // ended at the cutoff, not before
  // Requeued between the sweep's listing and its removal: kept.
  ASSERT_TRUE(store.transition(failed.id, JobState::kQueued, 600));
  EXPECT_FALSE(store.remove(failed.id, 1000000));
  EXPECT_TRUE(store.get(failed.id, false));
  // Without a cutoff, as DELETE /v1/jobs/{id}: anything goes.
  EXPECT_TRUE(store.remove(queued.id));
  EXPECT_TRUE(store.remove(failed.id));
  EXPECT_FALSE(store.remove(failed.id));
  EXPECT_FALSE(store.get(failed.id, false));
}

TYPED_TEST(JobStoreConformance, ADuplicateIdIsAStoreErrorNotOutOfSpace) {
  JobStore& store = this->store;
  JobRecord a = make_job(0, 1);
  store.create(a);
  try {
    store.create(a);
    ADD_FAILURE() << "a duplicate id was stored";
  } catch (const JobStoreError& e) {
    EXPECT_FALSE(e.out_of_space()) << e.what();
  }
  EXPECT_EQ(store.list({}).size(), 1u);
}

TYPED_TEST(JobStoreConformance, IdempotencyKeysArePerOwner) {
  JobStore& store = this->store;
  JobRecord a = make_job(0, 1);
  a.owner = "ann";
  a.idempotency_key = "k1";
  a.request_hash = "h1";
  store.create(a);
  auto found = store.find_by_idempotency_key("ann", "k1");
  ASSERT_TRUE(found);
  EXPECT_EQ(found->id, a.id);
  EXPECT_EQ(found->request_hash, "h1");
  EXPECT_FALSE(store.find_by_idempotency_key("bob", "k1"));
  JobRecord again = make_job(0, 2);
  again.owner = "ann";
  again.idempotency_key = "k1";
  EXPECT_THROW(store.create(again), JobStoreError);
  JobRecord bobs = again;
  bobs.id = new_job_id();
  bobs.owner = "bob";
  store.create(bobs);  // another owner's key of the same text
  EXPECT_EQ(store.find_by_idempotency_key("bob", "k1")->id, bobs.id);
  // Jobs without a key never collide.
  JobRecord n1 = make_job(0, 3), n2 = make_job(0, 4);
  store.create(n1);
  store.create(n2);
}

// The per-user queue cap reads these counts (JobService::queue_full): one owner's, or everyone's.
TYPED_TEST(JobStoreConformance, CountsJobsByStateAndOwner) {
  JobStore& store = this->store;
  this->job_in(JobState::kSucceeded, "ann");
  this->job_in(JobState::kRunning, "ann");
  this->job_in(JobState::kQueued, "ann");
  this->job_in(JobState::kQueued, "bob");
  this->job_in(JobState::kPaused, "bob");
  const auto ann = store.count_by_state(std::string("ann"));
  EXPECT_EQ(ann.at(JobState::kQueued), 1);
  EXPECT_EQ(ann.at(JobState::kRunning), 1);
  EXPECT_EQ(ann.at(JobState::kSucceeded), 1);
  EXPECT_EQ(ann.at(JobState::kPaused), 0);
  const auto all = store.count_by_state(std::nullopt);
  EXPECT_EQ(all.at(JobState::kQueued), 2);
  EXPECT_EQ(all.at(JobState::kPaused), 1);
  EXPECT_EQ(all.at(JobState::kCancelled), 0);
  EXPECT_EQ(all.size(), std::size(kAllJobStates));
  EXPECT_EQ(store.count_by_state(std::string("carol")).at(JobState::kQueued), 0);
}

TYPED_TEST(JobStoreConformance, KeepsNamesAndWarnings) {
  JobStore& store = this->store;
  JobRecord j = make_job(0, 1);
  j.name = "Cornell box, 4096 spp";
  store.create(j);
  EXPECT_EQ(store.get(j.id, false)->name, "Cornell box, 4096 spp");
  EXPECT_EQ(store.list({}).front().name, "Cornell box, 4096 spp");
  EXPECT_EQ(store.claim_next(2)->name, "Cornell box, 4096 spp");
  EXPECT_EQ(store.get(j.id, false)->warnings, "[]");
  store.set_warnings(j.id, R"(["KHR_materials_sheen is not supported"])");
  EXPECT_EQ(store.get(j.id, false)->warnings, R"(["KHR_materials_sheen is not supported"])");
}

TYPED_TEST(JobStoreConformance, AClaimStartsALeaseOfTheNextEpoch) {
  JobStore& store = this->store;
  JobRecord j = make_job(0, 1);
  store.create(j);
  EXPECT_EQ(store.get(j.id, false)->epoch, 0);
  auto claimed = store.claim_next(1000, 500);
  ASSERT_TRUE(claimed);
  EXPECT_EQ(claimed->epoch, 1);
  EXPECT_EQ(claimed->lease_expires_at_ms, 1500);
  EXPECT_TRUE(store.renew_lease(j.id, 1, 1400, 500));
  EXPECT_EQ(store.get(j.id, false)->lease_expires_at_ms, 1900);
  ASSERT_TRUE(store.end_run(j.id, 1, JobState::kQueued, 1500));  // the daemon stops: back to the queue
  EXPECT_FALSE(store.get(j.id, false)->lease_expires_at_ms);     // no run, no lease
  EXPECT_EQ(store.claim_next(1600, 500)->epoch, 2);              // every claim, a new epoch
}

// A node stops renewing (killed, paused past its lease, cut off): another claims the job under the next epoch, and
// whatever the first one writes afterwards, with its old epoch, is refused.
TYPED_TEST(JobStoreConformance, AnExpiredLeaseIsTakenOverAndTheOldEpochIsFenced) {
  JobRecord j = make_job(0, 1);
  this->store.create(j);
  std::unique_ptr<JobStore> other = this->backend.open("node-b");
  const JobRecord first = this->store.claim_next(0, 1000).value();
  EXPECT_FALSE(other->claim_next(999, 1000));  // leased
  EXPECT_TRUE(this->store.renew_lease(j.id, first.epoch, 900, 1000));
  EXPECT_FALSE(other->claim_next(1500, 1000));  // renewed until 1900
  const auto second = other->claim_next(1901, 1000);
  ASSERT_TRUE(second);
  EXPECT_EQ(second->id, j.id);
  EXPECT_EQ(second->epoch, first.epoch + 1);
  EXPECT_EQ(second->state, JobState::kRunning);
  EXPECT_EQ(second->document, j.document);

  JobProgress late;
  late.samples_done = 99;
  EXPECT_FALSE(this->store.update_progress(j.id, first.epoch, late));
  EXPECT_FALSE(this->store.renew_lease(j.id, first.epoch, 2000, 1000));
  EXPECT_FALSE(this->store.end_run(j.id, first.epoch, JobState::kSucceeded, 2000, "samples", ""));
  EXPECT_FALSE(this->store.end_run(j.id, first.epoch, JobState::kQueued, 2000));
  auto got = this->store.get(j.id, false);
  EXPECT_EQ(got->state, JobState::kRunning);
  EXPECT_EQ(got->epoch, second->epoch);
  EXPECT_EQ(got->progress.samples_done, 0u);

  JobProgress p;
  p.samples_done = 16;
  EXPECT_TRUE(other->update_progress(j.id, second->epoch, p));
  EXPECT_TRUE(other->end_run(j.id, second->epoch, JobState::kSucceeded, 2100, "samples", ""));
  got = this->store.get(j.id, false);
  EXPECT_EQ(got->state, JobState::kSucceeded);
  EXPECT_EQ(got->progress.samples_done, 16u);
}

// The job was cancelled, paused or deleted by a client while a node renders it: the node's next renewal, progress or
// end is refused, which is how it learns to stop.
TYPED_TEST(JobStoreConformance, ARunChangedElsewhereLosesItsLease) {
  JobStore& store = this->store;
  for (JobState elsewhere : {JobState::kCancelled, JobState::kPaused}) {
    SCOPED_TRACE(job_state_name(elsewhere));
    const JobRecord j = this->job_in(JobState::kRunning);
    ASSERT_TRUE(store.transition(j.id, elsewhere, 10, "cancelled", ""));
    EXPECT_FALSE(store.renew_lease(j.id, j.epoch, 11, 1000));
    EXPECT_FALSE(store.update_progress(j.id, j.epoch, JobProgress{}));
    EXPECT_FALSE(store.end_run(j.id, j.epoch, JobState::kSucceeded, 12, "samples", ""));
    EXPECT_EQ(store.get(j.id, false)->state, elsewhere);
    store.remove(j.id);
  }
  const JobRecord gone = this->job_in(JobState::kRunning);
  ASSERT_TRUE(store.remove(gone.id));
  EXPECT_FALSE(store.renew_lease(gone.id, gone.epoch, 11, 1000));
  EXPECT_FALSE(store.end_run(gone.id, gone.epoch, JobState::kSucceeded, 12, "samples", ""));
}

// A node ends its run while another cancels the job, at the same moment, through their own connections: exactly one
// of the two moves is made, and the job reads as the one that was (never succeeded over a cancel, nor the other way).
TYPED_TEST(JobStoreConformance, AnEndRacingACancelElsewhereIsOneOrTheOther) {
  std::unique_ptr<JobStore> other = this->backend.open("node-b");
  int ended = 0, cancelled = 0;
  for (int round = 0; round < 40; ++round) {
    const JobRecord j = this->job_in(JobState::kRunning);
    std::atomic<bool> go{false};
    bool end_taken = false, cancel_taken = false;
    std::thread renderer([&] {
      while (!go) std::this_thread::yield();
      end_taken = this->store.end_run(j.id, j.epoch, JobState::kSucceeded, 10, "samples", "");
    });
    std::thread client([&] {
      while (!go) std::this_thread::yield();
      cancel_taken = other->transition(j.id, JobState::kCancelled, 10, "cancelled", "");
    });
    go = true;
    renderer.join();
    client.join();
    ASSERT_NE(end_taken, cancel_taken) << "round " << round;
    EXPECT_EQ(this->store.get(j.id, false)->state, end_taken ? JobState::kSucceeded : JobState::kCancelled);
    (end_taken ? ended : cancelled)++;
    this->store.remove(j.id);
  }
  std::printf("end vs cancel at once, 40 rounds: the end won %d, the cancel %d\n", ended, cancelled);
}

// end_run makes only the moves out of running the state table allows.
TYPED_TEST(JobStoreConformance, AnEndOfARunFollowsTheStateTable) {
  JobStore& store = this->store;
  for (JobState to : kAllJobStates) {
    SCOPED_TRACE(job_state_name(to));
    const JobRecord j = this->job_in(JobState::kRunning);
    EXPECT_EQ(store.end_run(j.id, j.epoch, to, 5, "samples", ""), can_transition(JobState::kRunning, to));
    store.remove(j.id);
  }
}

TYPED_TEST(JobStoreConformance, ARestartRequeuesItsRunningJobsAndKeepsTheRest) {
  JobRecord done = make_job(0, 1), running = make_job(0, 2), queued = make_job(0, 3);
  {
    std::unique_ptr<JobStore> first = this->backend.open();
    first->create(done);
    first->create(running);
    first->create(queued);
    ASSERT_EQ(first->claim_next(5)->id, done.id);
    ASSERT_TRUE(first->transition(done.id, JobState::kSucceeded, 6, "samples", ""));
    const JobRecord claimed = first->claim_next(7).value();
    ASSERT_EQ(claimed.id, running.id);
    JobProgress p;
    p.passes = 2;
    p.samples_done = 3;
    ASSERT_TRUE(first->update_progress(running.id, claimed.epoch, p));
  }  // the process "dies" with one job running
  std::unique_ptr<JobStore> store = this->backend.open();
  EXPECT_EQ(store->requeue_running(), 1);
  auto r = store->get(running.id, false);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->state, JobState::kQueued);
  EXPECT_EQ(r->progress.samples_done, 0u);  // the progress starts over (the render resumes from its checkpoint)
  EXPECT_FALSE(r->started_at_ms);
  EXPECT_EQ(store->get(done.id, false)->state, JobState::kSucceeded);
  // The requeued job keeps its place: submitted before `queued`, it is claimed first.
  EXPECT_EQ(store->claim_next(8)->id, running.id);
  EXPECT_EQ(store->claim_next(8)->id, queued.id);
}

// A run is lost when its process dies without ending it: found by the next start (requeue_running) or by a claim of
// a run whose lease expired. Each loss counts once; a run ended on purpose (the daemon stopping puts the job back,
// a pause) counts none; a client's requeue of an ended job starts the count over.
TYPED_TEST(JobStoreConformance, LostRunsAreCountedOnceEach) {
  JobRecord job = make_job(0, 1);
  {
    std::unique_ptr<JobStore> first = this->backend.open();
    first->create(job);
    ASSERT_EQ(first->claim_next(10, 100)->lost_runs, 0);
  }  // the process dies with the job running
  std::unique_ptr<JobStore> store = this->backend.open();
  EXPECT_EQ(store->requeue_running(), 1);
  EXPECT_EQ(store->get(job.id)->lost_runs, 1);
  // Claimed again, and again it stops renewing: the next claim, past the lease, takes over a lost run.
  const JobRecord second = store->claim_next(20, 100).value();
  EXPECT_EQ(second.lost_runs, 1);
  const JobRecord third = store->claim_next(200, 100).value();
  EXPECT_EQ(third.lost_runs, 2);
  // Ended on purpose: no loss.
  ASSERT_TRUE(store->end_run(job.id, third.epoch, JobState::kQueued, 210));
  const JobRecord fourth = store->claim_next(220, 100).value();
  EXPECT_EQ(fourth.lost_runs, 2);
  ASSERT_TRUE(store->end_run(job.id, fourth.epoch, JobState::kPaused, 230));
  ASSERT_TRUE(store->transition(job.id, JobState::kQueued, 240));
  EXPECT_EQ(store->get(job.id)->lost_runs, 2);
  // Failed, then requeued by a client: the count starts over.
  const JobRecord fifth = store->claim_next(250, 100).value();
  ASSERT_TRUE(store->end_run(job.id, fifth.epoch, JobState::kFailed, 260, "", "it broke"));
  ASSERT_TRUE(store->transition(job.id, JobState::kQueued, 270));
  EXPECT_EQ(store->get(job.id)->lost_runs, 0);
}

// A frame range's units (work_units.h), alike on every store: each frame a unit of its own claimed in frame order,
// fenced by its run's epoch, its samples spp; the end unit claimable only once every frame is done, and its end the
// job's. A unit whose lease expired is taken over counting a lost run of its own; the job's progress sums its units.
TYPED_TEST(JobStoreConformance, AFrameRangesUnitsAreClaimedLeasedAndEndedFrameByFrame) {
  JobStore& store = this->store;
  JobRecord job = make_job(0, 1);
  job.settings = R"({"width":8,"height":8,"spp":4,"frames":{"start":1,"end":3,"step":1,"chunk":1}})";
  job.units = 3;
  job.progress.samples_total = 12;
  store.create(job);
  ASSERT_EQ(store.units(job.id).size(), 3u);
  EXPECT_EQ(store.units(job.id)[2].samples, 4u);
  auto first = store.claim_next(10, 1000);
  auto second = store.claim_next(10, 1000);
  ASSERT_TRUE(first && second);
  EXPECT_EQ(first->unit, 0);
  EXPECT_EQ(second->unit, 1);
  EXPECT_EQ(first->units, 3);
  EXPECT_NE(first->epoch, second->epoch);
  EXPECT_EQ(store.get(job.id)->state, JobState::kRunning);
  // Frame 1's run reports progress and ends; a stale epoch is fenced.
  JobProgress p;
  p.samples_done = 2;
  p.samples_total = 4;
  EXPECT_TRUE(store.update_progress(job.id, first->epoch, p));
  EXPECT_FALSE(store.update_progress(job.id, first->epoch + 100, p));
  EXPECT_TRUE(store.end_run(job.id, first->epoch, JobState::kSucceeded, 11));
  EXPECT_EQ(store.get(job.id)->progress.samples_done, 4u);
  EXPECT_FALSE(store.end_run(job.id, first->epoch, JobState::kSucceeded, 11));
  // Frame 2's node stops renewing: past its lease, the next claim takes frame 2 over (a lost run of that unit) before
  // frame 3.
  auto taken = store.claim_next(2000, 1000);
  ASSERT_TRUE(taken);
  EXPECT_EQ(taken->unit, 1);
  EXPECT_EQ(taken->unit_lost_runs, 1);
  EXPECT_FALSE(store.renew_lease(job.id, second->epoch, 2001, 1000));
  EXPECT_TRUE(store.renew_lease(job.id, taken->epoch, 2001, 1000));
  EXPECT_TRUE(store.end_run(job.id, taken->epoch, JobState::kSucceeded, 2002));
  // The end unit waits for frame 3.
  auto third = store.claim_next(2003, 1000);
  ASSERT_TRUE(third);
  EXPECT_EQ(third->unit, 2);
  EXPECT_FALSE(store.claim_next(2003, 1000));
  EXPECT_TRUE(store.end_run(job.id, third->epoch, JobState::kSucceeded, 2004));
  const std::vector<UnitRecord> units = store.units(job.id);
  EXPECT_TRUE(std::all_of(units.begin(), units.end(), [](const UnitRecord& u) { return u.done; }));
  auto end = store.claim_next(2005, 1000);
  ASSERT_TRUE(end);
  EXPECT_EQ(end->unit, 3);
  EXPECT_TRUE(store.end_run(job.id, end->epoch, JobState::kSucceeded, 2006, "samples"));
  EXPECT_EQ(store.get(job.id)->state, JobState::kSucceeded);
  // A unit's failure is its job's; a requeue then starts every frame over.
  JobRecord other = make_job(0, 2);
  other.settings = job.settings;
  other.units = 3;
  other.progress.samples_total = 12;
  store.create(other);
  auto done = store.claim_next(3000, 1000);
  ASSERT_TRUE(done && done->id == other.id);
  EXPECT_TRUE(store.end_run(other.id, done->epoch, JobState::kSucceeded, 3001));
  auto failing = store.claim_next(3002, 1000);
  ASSERT_TRUE(failing && failing->id == other.id);
  EXPECT_EQ(failing->unit_lost_runs, 0);
  EXPECT_TRUE(store.end_run(other.id, failing->epoch, JobState::kFailed, 3003, "", "frame 2: broken"));
  EXPECT_EQ(store.get(other.id)->state, JobState::kFailed);
  EXPECT_EQ(store.get(other.id)->error, "frame 2: broken");
  EXPECT_TRUE(store.transition(other.id, JobState::kQueued, 3004));
  const std::vector<UnitRecord> again = store.units(other.id);
  EXPECT_TRUE(std::none_of(again.begin(), again.end(), [](const UnitRecord& u) { return u.done || u.running; }));
}

// The per-owner cap counts a frame range's units as runs: a 2,000-frame range of one owner, at the cap, does not
// hold back another owner's still submitted after it.
TYPED_TEST(JobStoreConformance, AnOwnersCapCountsFrameUnitsSoALongRangeDoesNotStarveAnotherOwner) {
  JobStore& store = this->store;
  JobRecord range = make_job(0, 1);
  range.owner = "alice";
  range.settings = R"({"width":8,"height":8,"spp":1,"frames":{"start":1,"end":2000,"step":1,"chunk":1}})";
  range.units = 2000;
  range.progress.samples_total = 2000;
  store.create(range);
  JobRecord still = make_job(0, 2);
  still.owner = "bob";
  store.create(still);
  auto first = store.claim_next(10, 1000, 2);
  auto second = store.claim_next(10, 1000, 2);
  ASSERT_TRUE(first && second);
  EXPECT_EQ(first->id, range.id);
  EXPECT_EQ(second->id, range.id);
  // Alice holds two runs (two frames): Bob's still is next, before her third frame.
  auto third = store.claim_next(10, 1000, 2);
  ASSERT_TRUE(third);
  EXPECT_EQ(third->id, still.id);
  EXPECT_FALSE(store.claim_next(10, 1000, 2));  // Alice at her cap, Bob's only job running
  EXPECT_TRUE(store.end_run(range.id, first->epoch, JobState::kSucceeded, 11));
  auto next = store.claim_next(12, 1000, 2);
  ASSERT_TRUE(next);
  EXPECT_EQ(next->id, range.id);
  EXPECT_EQ(next->unit, 2);
}

}  // namespace
}  // namespace tessera::server
