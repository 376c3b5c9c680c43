// The job state machine: queued -> running -> succeeded | failed | cancelled, with running -> queued when a daemon
// stops (or died) mid-render and queued -> cancelled. One function decides every transition.
#pragma once

#include <optional>
#include <string>
#include <string_view>

namespace tessera::server {

enum class JobState { kQueued, kRunning, kSucceeded, kFailed, kCancelled };

const char* job_state_name(JobState s);
std::optional<JobState> parse_job_state(std::string_view name);
bool is_terminal(JobState s);
bool can_transition(JobState from, JobState to);

}  // namespace tessera::server
