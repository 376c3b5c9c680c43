#include "server/files/events.h"

#include <chrono>

namespace tessera::server {

EventHub::EventHub(size_t per_job_capacity, size_t global_capacity, size_t max_job_streams)
    : per_job_capacity_(per_job_capacity), global_capacity_(global_capacity), max_job_streams_(max_job_streams) {}

void EventHub::publish(const std::string& job_id, const std::string& owner, const std::string& type,
                       const std::string& data, bool terminal) {
  {
    std::lock_guard lock(mutex_);
    JobEvent e{0, type, job_id, owner, data, terminal};
    auto push = [](Stream& s, JobEvent ev, size_t capacity) {
      ev.seq = s.next_seq++;
      s.events.push_back(std::move(ev));
      while (s.events.size() > capacity) s.events.pop_front();
    };
    push(global_, e, global_capacity_);
    if (jobs_.size() >= max_job_streams_ && !jobs_.count(job_id)) {
      auto stalest = jobs_.begin();
      for (auto it = jobs_.begin(); it != jobs_.end(); ++it)
        if (it->second.touched < stalest->second.touched) stalest = it;
      jobs_.erase(stalest);
    }
    Stream& s = jobs_[job_id];
    s.touched = ++publish_count_;
    push(s, std::move(e), per_job_capacity_);
  }
  cv_.notify_all();
}

EventRead EventHub::read_locked(const Stream& s, uint64_t after) const {
  EventRead r;
  r.closed = closed_;
  r.last_seq = s.next_seq - 1;
  // A client that knows of events this stream never had (ids from before a restart) gets the stream afresh.
  if (after > r.last_seq) after = 0;
  if (!s.events.empty() && after + 1 < s.events.front().seq && after > 0) r.gap = true;
  for (const JobEvent& e : s.events)
    if (e.seq > after) r.events.push_back(e);
  return r;
}

EventRead EventHub::wait(const std::string& job_id, uint64_t after, int timeout_ms) {
  std::unique_lock lock(mutex_);
  ++watchers_;
  auto stream = [&]() -> const Stream* {
    if (job_id.empty()) return &global_;
    auto it = jobs_.find(job_id);
    return it == jobs_.end() ? nullptr : &it->second;
  };
  auto ready = [&] {
    if (closed_) return true;
    const Stream* s = stream();
    return s && s->next_seq - 1 > after;
  };
  cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms), ready);
  --watchers_;
  const Stream* s = stream();
  if (!s) {
    EventRead r;
    r.closed = closed_;
    return r;
  }
  return read_locked(*s, after);
}

uint64_t EventHub::last_seq(const std::string& job_id) {
  std::lock_guard lock(mutex_);
  if (job_id.empty()) return global_.next_seq - 1;
  auto it = jobs_.find(job_id);
  return it == jobs_.end() ? 0 : it->second.next_seq - 1;
}

void EventHub::forget(const std::string& job_id) {
  std::lock_guard lock(mutex_);
  jobs_.erase(job_id);
}

void EventHub::close() {
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
  }
  cv_.notify_all();
}

size_t EventHub::watchers() const {
  std::lock_guard lock(mutex_);
  return watchers_;
}

}  // namespace tessera::server
