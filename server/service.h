#pragma once
// The omnirig service: storage, worker pool and HTTP routes wired together. `omnirig serve`
// and the integration tests both run it through this class.

#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "api/job_types.h"
#include "server/events.h"
#include "server/http.h"
#include "server/metrics.h"
#include "server/worker_pool.h"
#include "storage/data_dir.h"
#include "storage/job_store.h"

namespace omnirig::server {

class LiveJobs;  // live_jobs.h

struct ServiceOptions {
  std::string host = "127.0.0.1";
  int port = 8080;  // 0 picks a free port
  std::filesystem::path data_dir = "./data";
  // The job store: empty for SQLite under data_dir (one machine), or a PostgreSQL URL shared by
  // the API servers and workers of several machines (postgresql://USER@HOST:PORT/DB).
  std::string database;
  std::filesystem::path web_dir;  // static files; empty: none
  std::string token;              // bearer token; required for non-loopback hosts
  // The job threads: workers.num_workers 0 is an API-only server (workers elsewhere, through
  // PostgreSQL); max_attempts also bounds the runs of a job a crash interrupted at start-up.
  WorkerPoolOptions workers;
  int http_threads = 256;   // one per open connection (see HttpServerOptions)
  int max_connections = 0;  // open HTTP connections at most, then 503 (0: no cap; see serve)
  int64_t max_file_bytes = 256LL << 20;  // an image (or .tum) upload
  int64_t max_video_bytes = 8LL << 30;   // a video upload (mp4, mkv, avi, ...)
  // A resumable upload's chunk (PUT with Content-Range) at most: the client sends a large file
  // in pieces this size or smaller; the server never holds more than a buffer of one.
  int64_t max_chunk_bytes = 64LL << 20;
  int64_t max_dataset_bytes = 8LL << 30;
  int64_t max_images_per_dataset = 20000;
  int64_t max_queued_jobs = 1000;
  // Free disk space to keep: uploads leaving less get 507, jobs leaving less fail (disk_full).
  int64_t min_free_bytes = 256LL << 20;
  // Job types added after the built-in ones (a type of the same name replaces it), e.g. a
  // test's own.
  std::vector<api::JobType> extra_job_types;
  void Check() const;  // throws InvalidArgument
};

// Default worker count for this machine: half the cores (at least 1), so a solver can use two.
int DefaultWorkers();
// Cores per job: the machine's cores shared among the workers.
int DefaultThreadsPerJob(int num_workers);

// Shared by the route files.
struct ServiceState {
  ServiceOptions options;
  // The job types this service accepts and its workers run: the built-in ones, "sample", and
  // options.extra_job_types.
  api::JobTypes job_types;
  std::unique_ptr<storage::DataDir> data_dir;
  std::unique_ptr<storage::JobStore> store;
  std::unique_ptr<JobEvents> events;  // GET /api/v1/events
  Metrics metrics;
  std::unique_ptr<WorkerPool> workers;
  std::unique_ptr<LiveJobs> live;  // live slam jobs running in this process (live_jobs.h)
  storage::ConsistencyReport consistency;
  storage::RecoveryReport recovery;
  double started_at = 0;
  ~ServiceState();  // service.cc, where LiveJobs is complete

  // Serialises the commit of an uploaded file (rename + record) with dataset deletion, so a
  // file and its record always describe the same upload.
  std::mutex files_mutex;
};

class Service {
 public:
  // Opens the data folder, checks consistency, recovers interrupted jobs and registers routes.
  // Throws on a bad configuration or an unusable data folder.
  explicit Service(const ServiceOptions& options);
  ~Service();

  // Binds, starts workers and the HTTP thread; returns the bound port.
  int Start();
  // SIGTERM: stops the HTTP listener, lets running jobs finish for up to `timeout_s`, then
  // re-queues the rest. Returns the number re-queued.
  int Drain(double timeout_s);

  ServiceState& state() { return *state_; }

 private:
  std::unique_ptr<ServiceState> state_;
  std::unique_ptr<HttpServer> http_;
};

// The record of a complete file on disk, checked as a plain PUT checks its body
// (routes_datasets.cc): a video's container, or an image's (or .tum's) header and completeness;
// HttpError 415 or 422 when it fails.
storage::ImageRecord CheckCompleteFile(const std::string& name, const std::filesystem::path& path);

// A route handler that runs `handler` on `state`.
inline HttpHandler WithState(ServiceState& state,
                             void (*handler)(ServiceState&, const HttpRequest&, HttpResponse&)) {
  return [&state, handler](const HttpRequest& request, HttpResponse& response) {
    handler(state, request, response);
  };
}

// Route registration (routes_*.cc).
void AddSystemRoutes(HttpServer& http, ServiceState& state);
void AddDatasetRoutes(HttpServer& http, ServiceState& state);
void AddJobRoutes(HttpServer& http, ServiceState& state);
void AddLiveRoutes(HttpServer& http, ServiceState& state);  // routes_live.cc

// The jobs `params` reference (JobType::referenced_jobs) exist (else 404), are of the type named
// and have succeeded (else 422). routes_jobs.cc; live jobs check theirs too.
void CheckReferencedJobs(ServiceState& state, const api::JobType& type,
                         const nlohmann::json& params);

}  // namespace omnirig::server
