#include "server/store/job_state.h"

#include <iterator>

namespace tessera::server {

namespace {

constexpr unsigned bit(JobState s) {
  return 1u << static_cast<unsigned>(s);
}

constexpr unsigned kAnyState = (1u << std::size(kAllJobStates)) - 1;

struct StateRow {
  JobState state;
  const char* name;
  bool terminal;
  unsigned into;  // the states a job in this state may move to
};

// Every move the job store accepts, whoever makes it (a client's action, a claim, the render's end, a daemon that
// stops mid-render).
constexpr StateRow kStates[] = {
    {JobState::kQueued, "queued", false, bit(JobState::kRunning) | bit(JobState::kPaused) | bit(JobState::kCancelled)},
    {JobState::kRunning, "running", false,
     bit(JobState::kQueued) | bit(JobState::kPaused) | bit(JobState::kSucceeded) | bit(JobState::kFailed) |
         bit(JobState::kCancelled)},
    {JobState::kPaused, "paused", false, bit(JobState::kQueued) | bit(JobState::kCancelled)},
    {JobState::kSucceeded, "succeeded", true, 0},
    {JobState::kFailed, "failed", true, bit(JobState::kQueued)},
    {JobState::kCancelled, "cancelled", true, bit(JobState::kQueued)},
};

struct ActionRow {
  JobAction action;
  const char* name;
  const char* verb;     // "cannot <verb> a job that is ..."
  const char* passive;  // "only a job that is ... can <passive>"
  unsigned from;        // the states it is allowed in
  std::optional<JobState> target;
  bool reruns;  // it runs the same document again: not for a job whose input the renderer refused
};

// What clients may ask, and where it leads. A paused running render keeps its checkpoint; resume puts it back in the
// queue to go on from it; requeue starts a failed or cancelled job from scratch (not one that failed on its input).
constexpr ActionRow kActions[] = {
    {JobAction::kCancel, "cancel", "cancel", "be cancelled",
     bit(JobState::kQueued) | bit(JobState::kRunning) | bit(JobState::kPaused), JobState::kCancelled, false},
    {JobAction::kPause, "pause", "pause", "be paused", bit(JobState::kQueued) | bit(JobState::kRunning),
     JobState::kPaused, false},
    {JobAction::kResume, "resume", "resume", "be resumed", bit(JobState::kPaused), JobState::kQueued, false},
    {JobAction::kRequeue, "requeue", "requeue", "be requeued", bit(JobState::kFailed) | bit(JobState::kCancelled),
     JobState::kQueued, true},
    {JobAction::kPriority, "priority", "change the priority of", "have its priority changed",
     bit(JobState::kQueued) | bit(JobState::kRunning) | bit(JobState::kPaused), std::nullopt, false},
    {JobAction::kDelete, "delete", "delete", "be deleted", kAnyState, std::nullopt, false},
};

constexpr const StateRow& row(JobState s) {
  return kStates[static_cast<unsigned>(s)];
}
constexpr const ActionRow& row(JobAction a) {
  return kActions[static_cast<unsigned>(a)];
}

// The tables are indexed by the enums, and every action that moves a job makes a move the state machine has.
constexpr bool tables_consistent() {
  for (unsigned i = 0; i < std::size(kStates); ++i)
    if (static_cast<unsigned>(kStates[i].state) != i || kStates[i].state != kAllJobStates[i]) return false;
  for (unsigned i = 0; i < std::size(kActions); ++i) {
    const ActionRow& a = kActions[i];
    if (static_cast<unsigned>(a.action) != i || a.action != kAllJobActions[i]) return false;
    if (!a.target) continue;
    for (JobState s : kAllJobStates)
      if ((a.from & bit(s)) && !(row(s).into & bit(*a.target))) return false;
  }
  return std::size(kStates) == std::size(kAllJobStates) && std::size(kActions) == std::size(kAllJobActions);
}
static_assert(tables_consistent());

// The states of a mask, in kAllJobStates order.
std::vector<JobState> states_of(unsigned mask) {
  std::vector<JobState> out;
  for (JobState s : kAllJobStates)
    if (mask & bit(s)) out.push_back(s);
  return out;
}

// "queued", "queued or running", "queued, running or paused".
std::string state_list(unsigned mask) {
  const std::vector<JobState> states = states_of(mask);
  std::string out;
  for (size_t i = 0; i < states.size(); ++i) {
    if (i > 0) out += i + 1 == states.size() ? " or " : ", ";
    out += kStates[static_cast<unsigned>(states[i])].name;
  }
  return out;
}

}  // namespace

const char* job_state_name(JobState s) {
  return row(s).name;
}

std::optional<JobState> parse_job_state(std::string_view name) {
  for (JobState s : kAllJobStates)
    if (name == job_state_name(s)) return s;
  return std::nullopt;
}

bool is_terminal(JobState s) {
  return row(s).terminal;
}

bool can_transition(JobState from, JobState to) {
  return (row(from).into & bit(to)) != 0;
}

std::vector<JobState> states_into(JobState to) {
  unsigned from = 0;
  for (const StateRow& r : kStates)
    if (r.into & bit(to)) from |= bit(r.state);
  return states_of(from);
}

const char* job_action_name(JobAction a) {
  return row(a).name;
}

bool action_allowed(JobAction a, JobState s, bool input_refused) {
  if (input_refused && s == JobState::kFailed && row(a).reruns) return false;
  return (row(a).from & bit(s)) != 0;
}

std::vector<JobState> action_states(JobAction a) {
  return states_of(row(a).from);
}

std::vector<JobAction> allowed_actions(JobState s, bool input_refused) {
  std::vector<JobAction> out;
  for (JobAction a : kAllJobActions)
    if (action_allowed(a, s, input_refused)) out.push_back(a);
  return out;
}

std::optional<JobState> action_target(JobAction a) {
  return row(a).target;
}

std::string action_refusal(JobAction a, JobState s, bool input_refused) {
  const ActionRow& r = row(a);
  if (input_refused && s == JobState::kFailed && r.reruns)
    return std::string("cannot ") + r.verb +
           " a job that failed on its input: the same document fails the same way; submit a corrected one";
  return std::string("cannot ") + r.verb + " a job that is " + job_state_name(s) + "; only a job that is " +
         state_list(r.from) + " can " + r.passive;
}

}  // namespace tessera::server
