#include "server/job_runner.h"

#include <atomic>
#include <chrono>
#include <cstdio>
#include <memory>
#include <mutex>

#include <nlohmann/json.hpp>

#include "api/job_types.h"
#include "api/service_json.h"
#include "engine/geometry/ply_preview.h"
#include "engine/util/check.h"
#include "server/dataset_recordings.h"
#include "storage/atomic_file.h"
#include "storage/image_header.h"

namespace omnirig::server {
namespace fs = std::filesystem;
using storage::JobState;

namespace {

// The per-attempt log file: timestamped lines, flushed as written, fsynced on close.
class JobLog {
 public:
  explicit JobLog(const fs::path& path) : path_(path), file_(std::fopen(path.c_str(), "a")) {}
  ~JobLog() { Close(); }
  void Write(const std::string& line) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!file_) return;
    const std::string stamp = api::TimeJson(storage::NowSeconds()).get<std::string>();
    std::fprintf(file_, "%s %s\n", stamp.c_str(), line.c_str());
    std::fflush(file_);
  }
  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!file_) return;
    std::fclose(file_);
    file_ = nullptr;
    try {
      storage::FsyncPath(path_);
    } catch (const std::exception&) {
      // The folder is gone: the attempt lost its lease and the run that took the job over
      // removed it. Nothing of this attempt is recorded, so nothing needs the log on disk.
    }
  }

 private:
  fs::path path_;
  std::mutex mutex_;
  FILE* file_;
};

// Writes progress to the store at most once per interval (and on every stage change), with an
// ETA from the attempt's elapsed time. Store errors are logged, never thrown into the engine.
class ProgressWriter {
 public:
  ProgressWriter(storage::JobStore& store, std::string job_id, double interval_s, JobLog& log,
                 std::function<void(const std::string&)> on_write)
      : store_(store),
        job_id_(std::move(job_id)),
        interval_s_(interval_s),
        log_(log),
        on_write_(std::move(on_write)) {}

  void Report(double fraction, const std::string& reported_stage, const std::string& message) {
    std::lock_guard<std::mutex> lock(mutex_);
    // "done" before the end is a part's end (e.g. the calibration inside a relative_pose job),
    // not the job's: the page must not say "done" while the job runs.
    const bool finished = fraction >= 1;
    const std::string stage = reported_stage != "done" || finished ? reported_stage
                              : last_stage_.empty()                  ? "running"
                                                                     : last_stage_;
    if (reported_stage == "done" && finished) summary_ = message;
    const auto now = std::chrono::steady_clock::now();
    const double since_write = std::chrono::duration<double>(now - last_write_).count();
    if (since_write < interval_s_ && stage == last_stage_ && fraction < 1) return;
    storage::JobProgress progress{std::clamp(fraction, 0.0, 1.0), stage, message, std::nullopt};
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    if (progress.fraction >= 0.01) {
      progress.eta_s = elapsed * (1 - progress.fraction) / progress.fraction;
    }
    try {
      store_.UpdateProgress(job_id_, progress);
      if (on_write_) on_write_(job_id_);
    } catch (const std::exception& e) {
      log_.Write(std::string("progress not stored: ") + e.what());
    }
    if (stage != last_stage_)
      log_.Write("stage " + stage + (message.empty() ? "" : ": " + message));
    last_write_ = now;
    last_stage_ = stage;
  }

  // The succeeded job's last progress: "done" with the engine's summary (its message at "done"),
  // never a stage left over from before the end.
  void Succeeded() {
    std::lock_guard<std::mutex> lock(mutex_);
    try {
      store_.UpdateProgress(job_id_, storage::JobProgress{1.0, "done", summary_, std::nullopt});
    } catch (const std::exception& e) {
      log_.Write(std::string("progress not stored: ") + e.what());
    }
  }

 private:
  storage::JobStore& store_;
  std::string job_id_;
  double interval_s_;
  JobLog& log_;
  std::function<void(const std::string&)> on_write_;
  std::mutex mutex_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point last_write_{};
  std::string last_stage_;
  std::string summary_;
};

// Lets one caller through per interval, whichever thread asks first after it has passed: engine
// threads ask often. Thread-safe and lock-free.
class IntervalGate {
 public:
  explicit IntervalGate(double interval_s)
      : interval_ns_(static_cast<int64_t>(interval_s * 1e9)), next_ns_(NowNs() + interval_ns_) {}

  // False always when the interval is 0 or less.
  bool Due() {
    if (interval_ns_ <= 0) return false;
    const int64_t now = NowNs();
    int64_t next = next_ns_.load(std::memory_order_relaxed);
    return now >= next && next_ns_.compare_exchange_strong(next, now + interval_ns_);
  }

 private:
  static int64_t NowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
  }
  int64_t interval_ns_;
  std::atomic<int64_t> next_ns_;
};

// A cancel recorded in the store by another process (a server on another machine sharing the
// queue), read from the store at most once per interval.
class StoreCancelWatcher {
 public:
  StoreCancelWatcher(storage::JobStore& store, std::string job_id, double interval_s)
      : store_(store), job_id_(std::move(job_id)), gate_(interval_s) {}

  bool CancelRequested() {
    if (seen_.load(std::memory_order_relaxed)) return true;
    if (!gate_.Due()) return false;
    try {
      const auto job = store_.GetJob(job_id_);
      if (job && job->cancel_requested) seen_ = true;
    } catch (const std::exception&) {
      // A store hiccup must not stop the job; the next check asks again.
    }
    return seen_.load();
  }

 private:
  storage::JobStore& store_;
  std::string job_id_;
  IntervalGate gate_;
  std::atomic<bool> seen_{false};
};

// The data folder's disk while a job runs: full once its free space is below the reserve. The
// run then stops at its next cancellation check, before it takes the last of the disk from the
// store and the uploads.
class DiskWatcher {
 public:
  DiskWatcher(const storage::DataDir& data_dir, int64_t min_free_bytes, double interval_s)
      : data_dir_(data_dir), min_free_bytes_(min_free_bytes), gate_(interval_s) {}

  // Throttled: reads the free space at most once per interval.
  bool Full() {
    if (full_.load(std::memory_order_relaxed)) return true;
    return gate_.Due() && FullNow();
  }
  bool FullNow() {
    if (data_dir_.FreeBytes() < min_free_bytes_) full_ = true;
    return full_.load();
  }
  bool full() const { return full_.load(); }

 private:
  const storage::DataDir& data_dir_;
  int64_t min_free_bytes_;
  IntervalGate gate_;
  std::atomic<bool> full_{false};
};

api::JobContext BuildContext(const storage::JobRecord& job, storage::JobStore& store,
                             const storage::DataDir& data_dir, const JobRunOptions& options,
                             const JobRunFlags& flags, const fs::path& output_dir,
                             ProgressWriter& progress, JobLog& log, DiskWatcher& disk) {
  api::JobContext context;
  context.job_id = job.id;
  context.dataset_id = job.dataset_id;
  context.dataset_dir = data_dir.ImagesDir(job.dataset_id);
  for (const storage::ImageRecord& image : store.ListImages(job.dataset_id)) {
    context.image_names.push_back(image.name);
  }
  context.open_recording = [dir = context.dataset_dir,
                            names = context.image_names](const std::string& name) {
    return OpenDatasetRecording(dir, names, name);
  };
  context.output_dir = output_dir;
  context.cache_dir = data_dir.CacheDir();
  context.num_threads = options.num_threads;
  context.progress.report = [&progress](double fraction, const std::string& stage,
                                        const std::string& message) {
    progress.Report(fraction, stage, message);
  };
  auto watcher = std::make_shared<StoreCancelWatcher>(store, job.id, options.store_cancel_check_s);
  context.progress.is_cancelled = [flags, watcher, &disk] {
    return (flags.cancel && flags.cancel->load()) ||
           (flags.interrupt && flags.interrupt->load()) || watcher->CancelRequested() ||
           disk.Full();
  };
  context.log = [&log](const std::string& line) { log.Write(line); };
  context.load_result = [&store](const std::string& job_id) {
    const auto other = store.GetJob(job_id);
    if (!other || other->state != JobState::kSucceeded) {
      throw InvalidArgument("job " + job_id +
                            " has no result (it does not exist or has not "
                            "succeeded)");
    }
    return nlohmann::json::parse(store.GetResult(job_id).value_or("null"));
  };
  context.artifact_path = [&store, &data_dir](const std::string& job_id, const std::string& name) {
    const auto other = store.GetJob(job_id);
    if (other && other->state == JobState::kSucceeded) {
      for (const storage::ArtifactRecord& artifact : store.ListArtifacts(job_id)) {
        if (artifact.name == name) return data_dir.root() / artifact.path;
      }
    }
    throw InvalidArgument("job " + job_id + " has no artifact " + name +
                          " (it does not exist, has not succeeded or did not write one)");
  };
  return context;
}

// Every regular file under `dir` as an artifact (name relative to dir), fsynced and hashed.
std::vector<storage::ArtifactRecord> CollectArtifacts(const fs::path& dir,
                                                      const fs::path& data_root) {
  std::vector<storage::ArtifactRecord> artifacts;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    const std::string name = fs::relative(entry.path(), dir).generic_string();
    if (storage::IsTemporaryFileName(entry.path().filename().string())) continue;
    storage::FsyncPath(entry.path());
    const storage::FileDigest digest = storage::DigestFile(entry.path());
    artifacts.push_back(
        storage::ArtifactRecord{name, fs::relative(entry.path(), data_root).generic_string(),
                                digest.size, digest.sha256, storage::ContentTypeForName(name)});
  }
  storage::FsyncPath(dir);
  std::sort(artifacts.begin(), artifacts.end(),
            [](const auto& a, const auto& b) { return a.name < b.name; });
  return artifacts;
}

storage::JobOutcome Failed(const std::string& code, const std::string& message) {
  storage::JobOutcome outcome;
  outcome.state = JobState::kFailed;
  outcome.error = storage::JobError{code, message};
  return outcome;
}

// The failure of a run that found the disk full; its outputs are already removed.
storage::JobOutcome DiskFull(const storage::JobRecord& job, const storage::DataDir& data_dir,
                             int64_t min_free_bytes) {
  const auto megabytes = [](int64_t bytes) {
    char text[32];
    std::snprintf(text, sizeof(text), "%.1f MB", static_cast<double>(bytes) / (1 << 20));
    return std::string(text);
  };
  return Failed("disk_full",
                "the disk holding the data folder is full (" + megabytes(data_dir.FreeBytes()) +
                    " free, the server keeps " + megabytes(min_free_bytes) +
                    "): this run's outputs were removed; free some space, then retry the job "
                    "(POST /api/v1/jobs/" +
                    job.id + "/retry)");
}

// Removes what the run wrote, except its log: on a full disk, so that the store has room to
// record the failure (and the uploads room again).
void RemoveOutputsButLog(const fs::path& output_dir) {
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(output_dir, error)) {
    if (entry.path().filename() != "log.txt") fs::remove_all(entry.path(), error);
  }
}

storage::JobOutcome RunJobType(const storage::JobRecord& job, const api::JobType* type,
                               const api::JobContext& context, const JobRunOptions& options,
                               const fs::path& output_dir, const fs::path& data_root) {
  if (!type) return Failed("unknown_type", "no job type '" + job.type + "' in this server");
  const nlohmann::json params = nlohmann::json::parse(job.params);
  context.progress.ThrowIfCancelled();
  const nlohmann::json result =
      options.run ? options.run(params, context) : type->run(params, context);
  storage::JobOutcome outcome;
  outcome.state = JobState::kSucceeded;
  outcome.result = result.dump();
  storage::WriteFileAtomically(output_dir / "result.json", result.dump(2));
  // Every large cloud the job wrote gets a preview the page loads by default.
  for (const PlyPreview& preview : WritePlyPreviews(output_dir, PlyPreviewOptions())) {
    context.Log("preview of a large cloud: " + fs::relative(preview.path, output_dir).string() +
                ", " + std::to_string(preview.preview_points) + " of " +
                std::to_string(preview.source_points) + " points");
  }
  outcome.artifacts = CollectArtifacts(output_dir, data_root);
  return outcome;
}

// The closed log's artifact record: a failed run's only artifact; a succeeded run's, collected
// before the log's last lines, gets its final size and hash.
void RecordLog(const fs::path& output_dir, const storage::DataDir& data_dir,
               storage::JobOutcome& outcome) {
  if (outcome.state != JobState::kSucceeded) {
    try {
      outcome.artifacts.clear();
      for (auto& artifact : CollectArtifacts(output_dir, data_dir.root())) {
        if (artifact.name == "log.txt") outcome.artifacts.push_back(artifact);
      }
    } catch (const std::exception&) {
      // The log is a courtesy for failed jobs; the outcome itself must still be recorded.
    }
  } else {
    // The log grew after the artifacts were collected: record its final size and hash.
    try {
      for (auto& artifact : outcome.artifacts) {
        if (artifact.name != "log.txt") continue;
        const auto digest = storage::DigestFile(output_dir / "log.txt");
        artifact.size = digest.size;
        artifact.sha256 = digest.sha256;
      }
    } catch (const std::exception& e) {
      outcome = Failed("job_failed", std::string("cannot record the log: ") + e.what());
    }
  }
}

}  // namespace

storage::JobOutcome RunJobAttempt(const storage::JobRecord& job, storage::JobStore& store,
                                  const storage::DataDir& data_dir, const api::JobTypes& job_types,
                                  const JobRunOptions& options, const JobRunFlags& flags) {
  const fs::path output_dir = data_dir.AttemptDir(job.id, job.attempts);
  std::error_code ignored;
  fs::remove_all(output_dir, ignored);
  fs::create_directories(output_dir);
  JobLog log(output_dir / "log.txt");
  log.Write("job " + job.id + " (" + job.type + ") attempt " + std::to_string(job.attempts) +
            " with " + std::to_string(options.num_threads) + " thread(s)");
  ProgressWriter progress(store, job.id, options.progress_interval_s, log, options.on_progress);
  DiskWatcher disk(data_dir, options.min_free_bytes, options.disk_check_s);
  storage::JobOutcome outcome;
  bool no_space = false;  // a write failed for want of space
  try {
    const api::JobContext context =
        BuildContext(job, store, data_dir, options, flags, output_dir, progress, log, disk);
    outcome = RunJobType(job, job_types.Find(job.type), context, options, output_dir,
                         data_dir.root());
    if (outcome.state == JobState::kSucceeded) progress.Succeeded();
  } catch (const Cancelled&) {
    outcome.state = JobState::kCanceled;
  } catch (const storage::StoreUnavailable& e) {
    // Not the job's fault: it goes back to the queue and runs again once the store is back.
    log.Write(std::string("the job store cannot be reached: ") + e.what());
    outcome.state = JobState::kQueued;
  } catch (const InvalidArgument& e) {
    outcome = Failed("invalid_input", e.what());
    if (!e.where().empty()) log.Write("check failed at " + e.where());  // the log, not the API
  } catch (const std::exception& e) {
    log.Write(std::string("error: ") + e.what());
    no_space = storage::IsDiskFull(e);
    outcome = Failed("job_failed", e.what());
  } catch (...) {
    outcome = Failed("job_failed", "unknown error");
  }
  // A run a user or a drain stopped is not the disk's; any other that left the disk full may
  // have lost a write the job type did not check, so it fails, whatever it returned.
  const bool stopped = outcome.state == JobState::kCanceled && !disk.full();
  if (outcome.state != JobState::kQueued && !stopped && (no_space || disk.FullNow())) {
    RemoveOutputsButLog(output_dir);
    outcome = DiskFull(job, data_dir, options.min_free_bytes);
  }
  log.Write(
      std::string("finished: ") + storage::JobStateName(outcome.state) +
      (outcome.error ? " (" + outcome.error->code + ": " + outcome.error->message + ")" : ""));
  log.Close();
  RecordLog(output_dir, data_dir, outcome);
  return outcome;
}

void RemoveOtherAttempts(const storage::DataDir& data_dir, const storage::JobRecord& job) {
  const fs::path keep = data_dir.AttemptDir(job.id, job.attempts);
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(data_dir.JobDir(job.id), error)) {
    if (entry.path() != keep) fs::remove_all(entry.path(), error);
  }
}

}  // namespace omnirig::server
