#pragma once
// The worker pool: a fixed number of threads, each taking the oldest queued job from the store
// and running its job type with a thread budget, so that workers x solver threads does not
// oversubscribe the cores. Computer-vision work runs here, never on an HTTP thread.
//
// A job's run gets a fresh output folder per attempt (every file there becomes an artifact
// when the job succeeds), a log (the `log.txt` artifact, kept for failed jobs too), throttled
// progress written to the store (so polls after a restart still see it) and a cancellation
// flag the cancel route sets.
//
// Leases: each claim is leased to this pool's worker id; a heartbeat thread renews the leases of
// the running jobs, records the worker as alive (with its running jobs) and re-queues jobs whose
// lease expired anywhere (another worker killed or cut off). A job whose lease this pool lost
// (the process was stopped past it) is interrupted and its end is not written: the run that took
// the job over owns it. With a store that notifies (PostgreSQL), a listener thread wakes idle
// workers on jobs queued by any process; the idle poll is only the fallback.
//
// A store that goes away (PostgreSQL stopped, restarted, killed) stops nothing: claims,
// heartbeats and a job's end are tried again until it is back, and a run that needed the store
// while it was gone is handed back to the queue rather than failed.

#include <atomic>
#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "api/job_types.h"
#include "server/metrics.h"
#include "storage/data_dir.h"
#include "storage/job_store.h"

namespace omnirig::server {

struct WorkerPoolOptions {
  int num_workers = 1;  // 0: an API-only server that runs no jobs
  int threads_per_job = 1;
  double progress_interval_s = 0.2;  // at most one progress write per job per interval
  double idle_poll_s = 0.5;          // re-check the store this often when idle
  int nice = 0;                      // scheduling niceness of worker threads (0: unchanged)
  // SCHED_IDLE for worker threads: they run only when nothing else on the machine wants the
  // CPU. Off by default: any busy process would starve the jobs.
  bool idle_scheduling = false;
  // Called with a job's id when this pool changed it (claimed, progress, finished, handed
  // back), e.g. JobEvents::Changed; may be empty.
  std::function<void(const std::string&)> on_job_changed;
  std::string worker_id;  // in leases and heartbeats; empty: HOST:PID
  double lease_s = 30;    // a claim's lease, renewed every lease_s / 3 while the job runs
  int max_attempts = 3;   // runs started before a job whose lease keeps expiring fails
  // Free space to keep on the data folder's disk: a job that leaves less fails with
  // "disk_full" (JobRunOptions::min_free_bytes).
  int64_t min_free_bytes = 0;
  void Check() const;
};

class WorkerPool {
 public:
  // `job_types`: the types the pool runs (a job of another type fails as unknown_type); it
  // must outlive the pool.
  WorkerPool(storage::JobStore& store, const storage::DataDir& data_dir,
             const api::JobTypes& job_types, Metrics& metrics, const WorkerPoolOptions& options);
  ~WorkerPool();  // Drain(0)

  void Start();
  // Wakes idle workers after a job was queued.
  void Notify();
  // Sets the cancel flag of a job running in this process; false when it is not running here.
  bool Cancel(const std::string& job_id);
  // Stops taking jobs (the running ones go on). Drain() begins with it; a service stopping calls
  // it before it hands its live jobs back to the queue, so that no worker here takes them.
  void StopClaiming();
  // Stops taking jobs, waits up to `timeout_s` for running ones, then interrupts the rest and
  // hands them back to the queue (their attempt is not counted). Returns the requeued count.
  int Drain(double timeout_s);

  int busy() const { return busy_.load(); }
  int size() const { return options_.num_workers; }
  const std::string& worker_id() const { return options_.worker_id; }

 private:
  struct RunningJob {
    std::string lease_token;
    std::atomic<bool> cancel{false};
    std::atomic<bool> interrupt{false};
    std::atomic<bool> lease_lost{false};
    std::atomic<bool> ending{false};  // its end is being written: the heartbeat leaves it alone
  };

  void WorkerLoop();
  void HeartbeatLoop();
  void Heartbeat();
  void ListenLoop();
  void RunJob(const storage::JobRecord& job);
  // Writes the end of a run to the store (its outcome, or the job handed back); returns whether
  // the store accepted it. A store that cannot be reached or whose disk is full is asked again,
  // with a growing pause, until it answers or the pool stops: a job never stays `running` for
  // a store that was away for a while. Given up, the job's lease expires and it is queued again.
  bool RecordEnd(const storage::JobRecord& job, RunningJob& running, bool hand_back,
                 const storage::JobOutcome& outcome);
  void WaitForWork(uint64_t seen_generation);

  storage::JobStore& store_;
  const storage::DataDir& data_dir_;
  const api::JobTypes& job_types_;
  Metrics& metrics_;
  WorkerPoolOptions options_;
  std::vector<std::thread> threads_;
  std::thread heartbeat_thread_, listener_thread_;
  double started_at_ = 0;
  std::atomic<int> busy_{0};

  std::mutex mutex_;
  std::condition_variable wake_;
  uint64_t generation_ = 0;  // bumped by Notify(); a worker waits only if it has not changed
  bool stopping_ = false;
  bool background_stopping_ = false;  // heartbeat and listener: after the workers stopped
  std::map<std::string, std::shared_ptr<RunningJob>> running_;
};

}  // namespace omnirig::server
