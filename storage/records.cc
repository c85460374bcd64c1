#include "storage/records.h"

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

}  // namespace omnirig::storage
