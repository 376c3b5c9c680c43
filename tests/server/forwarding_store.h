// A job store that hands every call to another one: tests derive from it and override only the calls they make fail,
// wait or count.
#pragma once

#include "server/store/job_store.h"

namespace tessera::server::test {

class ForwardingStore : public JobStore {
 public:
  explicit ForwardingStore(JobStore& inner) : inner_(inner) {}

  void create(const JobRecord& job) override { inner_.create(job); }
  std::optional<JobRecord> claim_next(int64_t now_ms, int64_t lease_ms, int max_running_per_owner) override {
    return inner_.claim_next(now_ms, lease_ms, max_running_per_owner);
  }
  bool renew_lease(const std::string& id, int64_t epoch, int64_t now_ms, int64_t lease_ms) override {
    return inner_.renew_lease(id, epoch, now_ms, lease_ms);
  }
  bool update_progress(const std::string& id, int64_t epoch, const JobProgress& p) override {
    return inner_.update_progress(id, epoch, p);
  }
  bool end_run(const std::string& id, int64_t epoch, JobState to, int64_t now_ms, const std::string& stop_reason,
               const std::string& error) override {
    return inner_.end_run(id, epoch, to, now_ms, stop_reason, error);
  }
  bool transition(const std::string& id, JobState to, int64_t now_ms, const std::string& stop_reason,
                  const std::string& error, std::optional<JobState> only_from) override {
    return inner_.transition(id, to, now_ms, stop_reason, error, only_from);
  }
  bool set_priority(const std::string& id, int priority) override { return inner_.set_priority(id, priority); }
  void set_warnings(const std::string& id, const std::string& w) override { inner_.set_warnings(id, w); }
  std::optional<int> queue_position(const std::string& id) override { return inner_.queue_position(id); }
  std::optional<JobRecord> find_by_idempotency_key(const std::string& owner, const std::string& key) override {
    return inner_.find_by_idempotency_key(owner, key);
  }
  std::map<JobState, int> count_by_state(const std::optional<std::string>& owner) override {
    return inner_.count_by_state(owner);
  }
  std::optional<JobRecord> get(const std::string& id, bool with_document) override {
    return inner_.get(id, with_document);
  }
  std::vector<JobRecord> list(const JobFilter& filter) override { return inner_.list(filter); }
  bool remove(const std::string& id, std::optional<int64_t> only_finished_before_ms) override {
    return inner_.remove(id, only_finished_before_ms);
  }
  int requeue_running() override { return inner_.requeue_running(); }
  bool splits_jobs() const override { return inner_.splits_jobs(); }
  std::vector<UnitRecord> units(const std::string& id) override { return inner_.units(id); }

 protected:
  JobStore& inner_;
};

}  // namespace tessera::server::test
