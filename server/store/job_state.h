// The job state machine and what clients may do in each state, in one table (job_state.cpp) that every part reads:
// the stores (which moves they accept), the job service (which requests it refuses, and with which message), the
// status JSON (its "actions" and links) and through it the web client's buttons.
//   queued  -> running (claimed), paused (by a client), cancelled
//   running -> queued (the daemon stopped or died mid-render; it resumes from its checkpoint), paused (by a client;
//              the render ends its pass and keeps its checkpoint), succeeded, failed, cancelled
//   paused  -> queued (resume), cancelled
//   failed, cancelled -> queued (requeue: from scratch), except a job that failed on its input
//   succeeded is final.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::server {

enum class JobState { kQueued, kRunning, kPaused, kSucceeded, kFailed, kCancelled };

inline constexpr JobState kAllJobStates[] = {JobState::kQueued,    JobState::kRunning, JobState::kPaused,
                                             JobState::kSucceeded, JobState::kFailed,  JobState::kCancelled};

const char* job_state_name(JobState s);
std::optional<JobState> parse_job_state(std::string_view name);
// Succeeded, failed or cancelled: the render will not run again unless a client requeues it.
bool is_terminal(JobState s);
bool can_transition(JobState from, JobState to);
// The states `to` may be reached from, in kAllJobStates order.
std::vector<JobState> states_into(JobState to);

// The stop reason a failed job records when the renderer refused its input (a scene or an asset it names that cannot
// be read): the same document fails the same way again, so such a job is not offered a requeue (a corrected document
// is submitted instead). A job that failed otherwise (a full disk, memory) may be requeued.
inline constexpr std::string_view kInputRefused = "input";

// What a client may ask of a job. Cancel, pause, resume and requeue move it to another state; priority changes its
// place in the queue; delete removes it in any state (cancelling its render first).
enum class JobAction { kCancel, kPause, kResume, kRequeue, kPriority, kDelete };

inline constexpr JobAction kAllJobActions[] = {JobAction::kCancel,  JobAction::kPause,    JobAction::kResume,
                                               JobAction::kRequeue, JobAction::kPriority, JobAction::kDelete};

// "cancel", "pause", "resume", "requeue", "priority", "delete": the names of the status JSON's "actions".
const char* job_action_name(JobAction a);
// `input_refused`: the job failed on its input (kInputRefused), which rules out what would run it again.
bool action_allowed(JobAction a, JobState s, bool input_refused = false);
// The states in which `a` is allowed, in kAllJobStates order.
std::vector<JobState> action_states(JobAction a);
// The actions allowed in `s`, in kAllJobActions order.
std::vector<JobAction> allowed_actions(JobState s, bool input_refused = false);
// The state an action moves a job to once it has taken effect (a running render first ends its pass); nothing for
// priority and delete.
std::optional<JobState> action_target(JobAction a);
// Why `a` is refused in `s`: "cannot pause a job that is succeeded; only a job that is queued or running can be
// paused".
std::string action_refusal(JobAction a, JobState s, bool input_refused = false);

}  // namespace tessera::server
