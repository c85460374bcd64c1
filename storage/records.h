#pragma once
// The records the service stores: datasets, their images, jobs and their artifacts. Plain data;
// job parameters and results are opaque JSON text here (storage knows records and files, not
// what a job computes). Times are seconds since the Unix epoch (UTC).

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace omnirig::storage {

enum class JobState { kQueued, kRunning, kSucceeded, kFailed, kCanceled };

// "queued", "running", "succeeded", "failed", "canceled".
const char* JobStateName(JobState state);
std::optional<JobState> ParseJobState(const std::string& name);
inline bool IsTerminal(JobState state) {
  return state == JobState::kSucceeded || state == JobState::kFailed ||
         state == JobState::kCanceled;
}
std::vector<JobState> AllJobStates();

// Seconds since the epoch, now, with sub-millisecond resolution.
double NowSeconds();

struct DatasetRecord {
  std::string id;
  std::string name;
  double created_at = 0;
  int64_t image_count = 0;  // files neither videos nor recordings (images, .tum trajectories)
  int64_t total_bytes = 0;  // of every file
  int64_t video_count = 0;  // files whose content type is video/*
};

struct ImageRecord {
  std::string name;  // relative path inside the dataset's image folder
  int64_t size = 0;
  std::string sha256;
  int width = 0, height = 0;
  std::string content_type;
};

struct JobProgress {
  double fraction = 0;  // [0, 1]
  std::string stage;
  std::string message;
  std::optional<double> eta_s;
};

struct JobError {
  std::string code;  // machine-friendly ("invalid_input", "job_failed", "interrupted")
  std::string message;
};

struct JobRecord {
  std::string id;
  std::string type;
  std::string dataset_id;
  std::string params;  // JSON text
  JobState state = JobState::kQueued;
  JobProgress progress;
  double created_at = 0;
  std::optional<double> started_at, finished_at;
  int attempts = 0;  // runs started, including ones interrupted by a crash
  std::optional<JobError> error;
  bool cancel_requested = false;
  // The lease of the last claim: the worker that ran (or runs) the job, the claim's token (a
  // worker's end of the job is accepted only while the token still matches) and, while running,
  // when the lease expires unless renewed. Empty before the first claim.
  std::string worker_id;
  std::string lease_token;
  std::optional<double> lease_expires_at;
};

// What a worker asks for when it claims a job: who it is and how long its lease lasts before
// a heartbeat must renew it.
struct ClaimRequest {
  std::string worker_id = "local";
  double lease_s = 60;
};

// A worker process seen by its heartbeat, with the jobs it was running then.
struct WorkerRecord {
  std::string id;
  double started_at = 0;
  double last_seen_at = 0;
  std::vector<std::string> running_jobs;
};

struct ArtifactRecord {
  std::string name;  // relative to the job's attempt folder
  std::string path;  // relative to the data folder
  int64_t size = 0;
  std::string sha256;
  std::string content_type;
};

// How a running job ended. Artifacts are recorded in the same transaction as the state.
struct JobOutcome {
  JobState state = JobState::kSucceeded;  // succeeded, failed or canceled
  std::optional<JobError> error;
  std::optional<std::string> result;  // JSON text, for succeeded jobs
  std::vector<ArtifactRecord> artifacts;
};

struct JobFilter {
  std::optional<JobState> state;
  std::optional<std::string> type;
  std::optional<std::string> dataset_id;
  int limit = 1000;  // negative: no limit
};

// What start-up recovery did with the jobs a crash left running.
struct RecoveryReport {
  std::vector<std::string> requeued, failed, canceled;
};

// A random 16-hex-digit identifier (records and lease tokens).
std::string NewId();

}  // namespace omnirig::storage
