#include "storage/records.h"

#include <algorithm>
#include <chrono>
#include <random>

namespace omnirig::storage {

const char* JobStateName(JobState state) {
  switch (state) {
    case JobState::kQueued:
      return "queued";
    case JobState::kRunning:
      return "running";
    case JobState::kSucceeded:
      return "succeeded";
    case JobState::kFailed:
      return "failed";
    case JobState::kCanceled:
      return "canceled";
  }
  return "unknown";
}

std::optional<JobState> ParseJobState(const std::string& name) {
  for (JobState state : AllJobStates()) {
    if (name == JobStateName(state)) return state;
  }
  return std::nullopt;
}

std::vector<JobState> AllJobStates() {
  return {JobState::kQueued, JobState::kRunning, JobState::kSucceeded, JobState::kFailed,
          JobState::kCanceled};
}

double NowSeconds() {
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  return std::chrono::duration<double>(now).count();
}

std::string NewId() {
  thread_local std::mt19937_64 engine{std::random_device{}()};
  static const char kHex[] = "0123456789abcdef";
  std::string id;
  uint64_t bits = engine();
  for (int i = 0; i < 16; ++i, bits >>= 4) id.push_back(kHex[bits & 15]);
  return id;
}

RecoveryAction DecideRecovery(bool cancel_requested, int64_t attempts, int max_attempts) {
  if (cancel_requested) return RecoveryAction::kCancel;
  if (attempts >= max_attempts) return RecoveryAction::kFail;
  return RecoveryAction::kRequeue;
}

std::string InterruptedMessage(int64_t attempts, int max_attempts) {
  return "the job's worker stopped during each of its " + std::to_string(attempts) +
         " attempts (maximum " + std::to_string(max_attempts) + ")";
}

std::string JoinIds(const std::vector<std::string>& ids) {
  std::string joined;
  for (const std::string& id : ids) joined += (joined.empty() ? "" : ",") + id;
  return joined;
}

std::vector<std::string> SplitIds(const std::string& joined) {
  std::vector<std::string> ids;
  size_t start = 0;
  while (start < joined.size()) {
    const size_t comma = std::min(joined.find(',', start), joined.size());
    if (comma > start) ids.push_back(joined.substr(start, comma - start));
    start = comma + 1;
  }
  return ids;
}

}  // namespace omnirig::storage
