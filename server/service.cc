#include "server/service.h"

#include <iostream>
#include <thread>

#include <algorithm>
#include <mutex>

#include "api/job_types.h"
#include "api/sample_job.h"
#include "engine/util/check.h"
#include "server/live_jobs.h"
#include "server/log_line.h"
#include "storage/atomic_file.h"
#include "storage/postgres_job_store.h"
#include "storage/sqlite_job_store.h"

namespace omnirig::server {

void ServiceOptions::Check() const {
  OMNIRIG_CHECK(port >= 0 && port <= 65535, "--port must be in [0, 65535], got " << port);
  OMNIRIG_CHECK(!data_dir.empty(), "--data must name a folder");
  OMNIRIG_CHECK(workers.num_workers >= 0 && workers.num_workers <= 256,
                "--workers must be in [0, 256]");
  OMNIRIG_CHECK(database.empty() || storage::IsPostgresUrl(database),
                "--database must be a postgresql:// URL (or omitted for SQLite under --data)");
  OMNIRIG_CHECK(workers.lease_s > 0, "--lease-seconds must be positive");
  OMNIRIG_CHECK(workers.threads_per_job >= 1, "--threads-per-job must be at least 1");
  OMNIRIG_CHECK(http_threads >= 2, "--http-threads must be at least 2");
  OMNIRIG_CHECK(max_connections >= 0, "--max-connections must not be negative");
  OMNIRIG_CHECK(workers.nice >= 0 && workers.nice <= 19, "--worker-nice must be in [0, 19]");
  OMNIRIG_CHECK(workers.max_attempts >= 1, "--max-attempts must be at least 1");
  OMNIRIG_CHECK(max_file_bytes > 0 && max_dataset_bytes >= max_file_bytes,
                "--max-file-mb must be positive and at most --max-dataset-mb");
  OMNIRIG_CHECK(max_video_bytes > 0, "--max-video-mb must be positive");
  OMNIRIG_CHECK(max_chunk_bytes >= (64 << 10), "--max-chunk-mb must be at least 64 KiB");
  OMNIRIG_CHECK(max_images_per_dataset >= 1 && max_queued_jobs >= 1,
                "--max-images and --max-queued-jobs must be at least 1");
  OMNIRIG_CHECK(min_free_bytes >= 0, "--min-free-mb must not be negative");
  OMNIRIG_CHECK(IsLoopbackHost(host) || !token.empty(),
                "refusing to listen on non-loopback address "
                    << host << " without a bearer token (--token or OMNIRIG_TOKEN)");
}

int DefaultWorkers() {
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  return std::max(1, cores / 2);
}

int DefaultThreadsPerJob(int num_workers) {
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  return std::max(1, cores / std::max(1, num_workers));
}

namespace {

// The job store `database` names (see ServiceOptions::database), migrated.
std::unique_ptr<storage::JobStore> OpenJobStore(const std::string& database,
                                                const storage::DataDir& data_dir) {
  if (storage::IsPostgresUrl(database))
    return std::make_unique<storage::PostgresJobStore>(database);
  OMNIRIG_CHECK(database.empty(),
                "unsupported --database '" << database << "' (expected postgresql://...)");
  return std::make_unique<storage::SqliteJobStore>(data_dir.DatabasePath().string());
}

// The "sample" job's files (api/sample_job.h) moved into the dataset with their records, under
// the lock that dataset deletion takes; returns how many were added.
size_t AddSampleFiles(ServiceState& state, const std::string& dataset_id,
                      const std::filesystem::path& dir) {
  namespace fs = std::filesystem;
  std::vector<std::pair<fs::path, std::string>> files;  // rendered path, name in the dataset
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    const std::string extension = entry.path().extension().string();
    if (extension != ".png" && extension != ".tum") continue;
    files.emplace_back(entry.path(), fs::relative(entry.path(), dir).generic_string());
  }
  std::sort(files.begin(), files.end());
  std::lock_guard<std::mutex> lock(state.files_mutex);
  if (!state.store->GetDataset(dataset_id)) {
    throw InvalidArgument("dataset " + dataset_id + " was deleted while the sample rendered");
  }
  const fs::path images_dir = state.data_dir->ImagesDir(dataset_id);
  std::vector<storage::ImageRecord> records;
  for (const auto& [path, name] : files) {
    records.push_back(CheckCompleteFile(name, path));  // as an upload records it
    fs::create_directories((images_dir / name).parent_path());
    fs::rename(path, images_dir / name);
    storage::FsyncPath((images_dir / name).parent_path());
  }
  state.store->PutImages(dataset_id, records);
  return records.size();
}

void PrintStartupReport(const ServiceState& state) {
  const auto& consistency = state.consistency;
  const auto& recovery = state.recovery;
  std::cerr << "omnirig: data in " << state.data_dir->root().string() << ", integrity "
            << consistency.integrity << ", " << consistency.temporary_files_removed
            << " interrupted write(s) removed, " << consistency.missing_images.size()
            << " missing image(s) dropped, " << consistency.missing_artifacts.size()
            << " missing artifact(s); recovery: " << recovery.requeued.size() << " requeued, "
            << recovery.failed.size() << " failed, " << recovery.canceled.size() << " canceled"
            << std::endl;
  for (const auto& name : consistency.missing_artifacts) {
    std::cerr << "omnirig: artifact missing or resized on disk: " << name << std::endl;
  }
}

}  // namespace

Service::Service(const ServiceOptions& options) : state_(std::make_unique<ServiceState>()) {
  options.Check();
  ServiceState& state = *state_;
  api::AddBuiltinJobTypes(&state.job_types);
  state.job_types.Add(
      api::SampleJobType([&state](const std::string& dataset_id, const std::filesystem::path& dir) {
        return AddSampleFiles(state, dataset_id, dir);
      }));
  for (const api::JobType& type : options.extra_job_types) state.job_types.Add(type);
  state.options = options;
  state.started_at = storage::NowSeconds();
  state.data_dir = std::make_unique<storage::DataDir>(options.data_dir);
  state.store = OpenJobStore(options.database, *state.data_dir);
  if (options.database.empty()) {
    state.consistency = storage::CheckConsistency(*state.data_dir, *state.store);
  } else {
    // A shared store and folder: other processes are writing right now (temporary files,
    // new datasets), so start-up repairs would race them. Only the store's check runs.
    state.consistency.integrity = state.store->IntegrityCheck();
  }
  if (state.consistency.integrity != "ok") {
    throw std::runtime_error("the job store fails its integrity check: " +
                             state.consistency.integrity);
  }
  // SQLite is this process's alone: whatever it left running was interrupted. PostgreSQL is
  // shared: only jobs whose lease expired are (the others run on live workers elsewhere).
  state.recovery = options.database.empty()
                       ? state.store->RecoverInterruptedJobs(options.workers.max_attempts)
                       : state.store->RecoverExpiredLeases(options.workers.max_attempts);
  state.events = std::make_unique<JobEvents>(*state.store);
  PrintStartupReport(state);
  LogRecovery(*state.store, state.recovery,
              options.database.empty() ? "interrupted" : "lease_expired");
  WorkerPoolOptions pool_options = options.workers;
  pool_options.min_free_bytes = options.min_free_bytes;  // one reserve for uploads and jobs
  pool_options.on_job_changed = [events = state.events.get()](const std::string& id) {
    events->Changed(id);
  };
  // NOTIFY wakes idle workers at once; the poll only covers a lost notification.
  if (state.store->NotifiesQueueChanges()) pool_options.idle_poll_s = 5;
  state.metrics.SetWorkerAliveWindow(options.workers.lease_s);
  state.workers = std::make_unique<WorkerPool>(*state.store, *state.data_dir, state.job_types,
                                               state.metrics, pool_options);
  state.live = std::make_unique<LiveJobs>(state);

  HttpServerOptions http_options;
  http_options.num_threads = options.http_threads;
  http_options.max_connections = options.max_connections;
  http_options.max_body_bytes = options.max_dataset_bytes;
  http_options.token = options.token;
  http_ = std::make_unique<HttpServer>(
      http_options, [&state](const std::string& route, int status, double seconds) {
        state.metrics.CountRequest(route, status, seconds);
      });
  state.metrics.SetOpenConnectionsGauge([http = http_.get()] { return http->OpenConnections(); });
  AddSystemRoutes(*http_, state);
  AddDatasetRoutes(*http_, state);
  AddJobRoutes(*http_, state);
  AddLiveRoutes(*http_, state);
}

ServiceState::~ServiceState() = default;

Service::~Service() {
  if (state_ && state_->events) state_->events->Close();
  if (http_) http_->Stop();
  if (state_ && state_->workers) state_->workers->StopClaiming();
  if (state_ && state_->live) state_->live->Drain();
  if (state_ && state_->workers) state_->workers->Drain(0);
}

int Service::Start() {
  const int port = http_->Bind(state_->options.host, state_->options.port);
  state_->workers->Start();
  http_->Start();
  return port;
}

int Service::Drain(double timeout_s) {
  state_->events->Close();  // ends the event streams, which would hold the HTTP threads
  http_->Stop();
  // Live jobs go back to the queue as batch jobs, for a worker of another server (or of this
  // one's next start): this one's workers take no more jobs first.
  state_->workers->StopClaiming();
  const int live = state_->live->Drain();
  return live + state_->workers->Drain(timeout_s);
}

}  // namespace omnirig::server
