// The job queue under load: 1,000 trivial jobs (test_sleep, one step, no sleep: the
// run is the queue, the job folder, log and result files) through 1, 2 and 4 workers, SQLite
// (worker threads in one process: SQLite is one machine's store) beside PostgreSQL (`omnirig
// worker` processes, this binary re-executed, on a real PostgreSQL started here with fsync on).
//
// Reports jobs per second over the whole batch (all queued at once: first claim to last end)
// and the claim latency of a job queued while a worker is idle (queued -> started, one job at a
// time, p50/p99), which NOTIFY should keep far under 50 ms (the idle poll is 5 s).
//
//   bench_job_queue [--jobs 1000] [--probes 200] [--workers 1,2,4]

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <functional>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "api/job_types.h"
#include "server/commands.h"
#include "server/metrics.h"
#include "server/worker_pool.h"
#include "storage/data_dir.h"
#include "storage/postgres_job_store.h"
#include "storage/sqlite_job_store.h"
#include "testing/storage/postgres_test_server.h"
#include "testing/storage/test_util.h"
#include "tests/server_test_util.h"

namespace {

using omnirig::storage::JobState;
namespace fs = std::filesystem;
namespace storage = omnirig::storage;
namespace server = omnirig::server;

constexpr char kTrivialParams[] = R"({"steps": 1, "step_ms": 0, "output_kb": 0})";

struct Figures {
  double jobs_per_s = 0;
  double claim_p50_ms = 0, claim_p99_ms = 0;
};

double Percentile(std::vector<double> values, double q) {
  std::sort(values.begin(), values.end());
  const size_t index = std::min(values.size() - 1, static_cast<size_t>(q * (values.size() - 1)));
  return values[index];
}

void WaitUntilDone(storage::JobStore& store, int64_t total) {
  while (true) {
    const auto counts = store.CountJobsByState();
    if (counts.at(JobState::kSucceeded) + counts.at(JobState::kFailed) +
            counts.at(JobState::kCanceled) >=
        total) {
      return;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

// Runs the batch and the idle probes on `store`, with workers already running; `notify` wakes
// in-process workers (the service's POST /jobs does the same).
Figures Measure(storage::JobStore& store, int jobs, int probes,
                const std::function<void()>& notify) {
  Figures figures;
  for (int i = 0; i < jobs; ++i) store.CreateJob("test_sleep", "bench", kTrivialParams);
  notify();
  WaitUntilDone(store, jobs);
  storage::JobFilter all;
  all.limit = -1;
  double first_start = 1e300, last_end = 0;
  for (const auto& job : store.ListJobs(all)) {
    if (job.state != JobState::kSucceeded) {
      std::cerr << "job " << job.id << " ended " << storage::JobStateName(job.state) << std::endl;
    }
    first_start = std::min(first_start, job.started_at.value_or(1e300));
    last_end = std::max(last_end, job.finished_at.value_or(0));
  }
  figures.jobs_per_s = jobs / (last_end - first_start);

  std::vector<double> latencies_ms;
  for (int i = 0; i < probes; ++i) {
    const auto job = store.CreateJob("test_sleep", "bench", kTrivialParams);
    notify();
    std::optional<storage::JobRecord> now;
    while (!(now = store.GetJob(job.id)) || !omnirig::storage::IsTerminal(now->state)) {
      std::this_thread::sleep_for(std::chrono::microseconds(500));
    }
    latencies_ms.push_back((*now->started_at - job.created_at) * 1e3);
  }
  figures.claim_p50_ms = Percentile(latencies_ms, 0.5);
  figures.claim_p99_ms = Percentile(latencies_ms, 0.99);
  return figures;
}

server::WorkerPoolOptions PoolOptions(int workers) {
  server::WorkerPoolOptions options;
  options.num_workers = workers;
  options.threads_per_job = 1;
  options.nice = 0;
  options.idle_scheduling = false;
  return options;
}

Figures RunSqlite(int workers, int jobs, int probes) {
  storage::testing::TempDir dir;
  storage::DataDir data(dir.path());
  storage::SqliteJobStore store(data.DatabasePath().string());
  server::Metrics metrics;
  omnirig::api::JobTypes job_types;
  omnirig::api::AddBuiltinJobTypes(&job_types);
  job_types.Add(omnirig::testing::SleepJobType());
  server::WorkerPool pool(store, data, job_types, metrics, PoolOptions(workers));
  pool.Start();
  const Figures figures = Measure(store, jobs, probes, [&pool] { pool.Notify(); });
  pool.Drain(10);
  return figures;
}

pid_t StartWorkerProcess(const std::string& url, const fs::path& data, const std::string& id) {
  int out[2];
  if (::pipe(out) != 0) throw std::runtime_error("pipe failed");
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::dup2(out[1], STDOUT_FILENO);
    const int quiet = ::open("/dev/null", O_WRONLY);
    if (quiet >= 0) ::dup2(quiet, STDERR_FILENO);  // the table stays readable
    ::close(out[0]);
    const std::vector<std::string> args = {
        "/proc/self/exe", "--worker", "--database",        url, "--data",        data.string(),
        "--threads",      "1",        "--threads-per-job", "1", "--worker-nice", "0",
        "--worker-id",    id};
    std::vector<char*> argv;
    for (const auto& arg : args) argv.push_back(const_cast<char*>(arg.c_str()));
    argv.push_back(nullptr);
    ::execv("/proc/self/exe", argv.data());
    ::_exit(127);
  }
  ::close(out[1]);
  char c;
  while (::read(out[0], &c, 1) == 1 && c != '\n') {
  }
  ::close(out[0]);
  return pid;
}

Figures RunPostgres(storage::testing::PostgresTestServer& postgres, int workers, int jobs,
                    int probes) {
  storage::testing::TempDir dir;
  const std::string url = postgres.CreateDatabase();
  storage::PostgresJobStore store(url, 2);
  std::vector<pid_t> pids;
  for (int w = 0; w < workers; ++w) {
    pids.push_back(StartWorkerProcess(url, dir.path(), "bench-" + std::to_string(w)));
  }
  const Figures figures = Measure(store, jobs, probes, [] {});
  for (const pid_t pid : pids) ::kill(pid, SIGTERM);
  for (const pid_t pid : pids) ::waitpid(pid, nullptr, 0);
  return figures;
}

std::vector<int> ParseList(const std::string& text) {
  std::vector<int> values;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) values.push_back(std::stoi(item));
  return values;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && std::string(argv[1]) == "--worker") {
    return server::WorkerCommand(std::vector<std::string>(argv + 2, argv + argc),
                                 {omnirig::testing::SleepJobType()});
  }
  int jobs = 1000, probes = 200;
  std::vector<int> worker_counts = {1, 2, 4};
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--jobs") jobs = std::atoi(argv[i + 1]);
    if (flag == "--probes") probes = std::atoi(argv[i + 1]);
    if (flag == "--workers") worker_counts = ParseList(argv[i + 1]);
  }
  storage::testing::PostgresTestServerOptions options;
  options.fsync = true;  // what a deployment runs
  storage::testing::PostgresTestServer postgres(options);
  std::printf("%d trivial jobs; claim latency of a job queued with a worker idle (%d probes)\n",
              jobs, probes);
  std::printf("%-8s | %-34s | %-34s\n", "", "SQLite (threads in one process)",
              "PostgreSQL (worker processes)");
  std::printf("%-8s | %10s %11s %11s | %10s %11s %11s | %s\n", "workers", "jobs/s", "claim p50",
              "claim p99", "jobs/s", "claim p50", "claim p99", "PG/SQLite jobs/s");
  for (const int workers : worker_counts) {
    const Figures sqlite = RunSqlite(workers, jobs, probes);
    const Figures pg = RunPostgres(postgres, workers, jobs, probes);
    std::printf("%-8d | %10.1f %8.2f ms %8.2f ms | %10.1f %8.2f ms %8.2f ms | %.2f\n", workers,
                sqlite.jobs_per_s, sqlite.claim_p50_ms, sqlite.claim_p99_ms, pg.jobs_per_s,
                pg.claim_p50_ms, pg.claim_p99_ms, pg.jobs_per_s / sqlite.jobs_per_s);
    std::fflush(stdout);
  }
  return 0;
}
