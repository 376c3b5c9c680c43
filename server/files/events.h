// The event bus behind Server-Sent Events: what happened to jobs, kept so that a client reconnecting with
// Last-Event-ID misses nothing still kept. One stream per job (ids count that job's events) and one global stream
// (ids count every event). EventBus is the interface the daemon publishes to and streams from; EventHub keeps the
// events of one process in memory, in bounded ring buffers. Publishing never blocks on a watcher; watchers wait on a
// condition variable.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace tessera::server {

struct JobEvent {
  uint64_t seq = 0;  // in the stream it was read from
  std::string type;  // "state" | "progress" | "preview"
  std::string job_id;
  std::string owner;      // who may see it
  std::string data;       // the JSON of the data: line
  bool terminal = false;  // a state event into succeeded, failed or cancelled
};

struct EventRead {
  std::vector<JobEvent> events;  // after the asked sequence number, oldest first
  bool gap = false;              // some asked-for events have left the buffer
  bool closed = false;           // the hub is shutting down
  uint64_t last_seq = 0;         // the stream's newest sequence number
};

class EventBus {
 public:
  virtual ~EventBus() = default;

  virtual void publish(const std::string& job_id, const std::string& owner, const std::string& type,
                       const std::string& data, bool terminal = false) = 0;
  // Waits up to `timeout_ms` for events after `after` in the job's stream (or the global one when `job_id` is
  // empty), and returns them.
  virtual EventRead wait(const std::string& job_id, uint64_t after, int timeout_ms) = 0;
  virtual uint64_t last_seq(const std::string& job_id) = 0;
  // A deleted job's stream is dropped.
  virtual void forget(const std::string& job_id) = 0;
  // Wakes every watcher for good (daemon shutdown).
  virtual void close() = 0;
  // Streams waiting for events in this process.
  virtual size_t watchers() const = 0;
};

class EventHub final : public EventBus {
 public:
  explicit EventHub(size_t per_job_capacity = 256, size_t global_capacity = 4096, size_t max_job_streams = 4096);

  void publish(const std::string& job_id, const std::string& owner, const std::string& type, const std::string& data,
               bool terminal = false) override;
  EventRead wait(const std::string& job_id, uint64_t after, int timeout_ms) override;
  uint64_t last_seq(const std::string& job_id) override;
  void forget(const std::string& job_id) override;
  void close() override;
  size_t watchers() const override;

 private:
  struct Stream {
    std::deque<JobEvent> events;
    uint64_t next_seq = 1;
    uint64_t touched = 0;  // publish order, to drop the stalest stream when there are too many
  };
  EventRead read_locked(const Stream& s, uint64_t after) const;

  const size_t per_job_capacity_, global_capacity_, max_job_streams_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  Stream global_;
  std::map<std::string, Stream> jobs_;
  uint64_t publish_count_ = 0;
  bool closed_ = false;
  size_t watchers_ = 0;
};

}  // namespace tessera::server
