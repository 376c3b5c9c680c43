// The job state machine. One function, can_transition(), decides every move:
//   queued  -> running (claimed), paused (by a client), cancelled
//   running -> queued (the daemon stopped or died mid-render; it resumes from its checkpoint), paused (by a client;
//              the render ends its pass and keeps its checkpoint), succeeded, failed, cancelled
//   paused  -> queued (resume), cancelled
//   failed, cancelled -> queued (requeue: from scratch)
//   succeeded is final.
#pragma once

#include <optional>
#include <string>
#include <string_view>

namespace tessera::server {

enum class JobState { kQueued, kRunning, kPaused, kSucceeded, kFailed, kCancelled };

inline constexpr JobState kAllJobStates[] = {JobState::kQueued,    JobState::kRunning, JobState::kPaused,
                                             JobState::kSucceeded, JobState::kFailed,  JobState::kCancelled};

const char* job_state_name(JobState s);
std::optional<JobState> parse_job_state(std::string_view name);
// Succeeded, failed or cancelled: the render will not run again unless a client requeues it.
bool is_terminal(JobState s);
bool can_transition(JobState from, JobState to);

}  // namespace tessera::server
