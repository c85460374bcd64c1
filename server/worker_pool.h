#pragma once
// The worker pool: a fixed number of threads, each taking the oldest queued job from the store
// and running its job type with a thread budget, so that workers x solver threads does not
// oversubscribe the cores. Computer-vision work runs here, never on an HTTP thread.
//
// A job's run gets a fresh output folder per attempt (every file there becomes an artifact
// when the job succeeds), a log (the `log.txt` artifact, kept for failed jobs too), throttled
// progress written to the store (so polls after a restart still see it) and a cancellation
// flag the cancel route sets.

#include <atomic>
#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "server/metrics.h"
#include "storage/data_dir.h"
#include "storage/job_store.h"

namespace omnirig::server {

struct WorkerPoolOptions {
  int num_workers = 1;
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
  void Check() const;
};

class WorkerPool {
 public:
  WorkerPool(storage::JobStore& store, const storage::DataDir& data_dir, Metrics& metrics,
             const WorkerPoolOptions& options);
  ~WorkerPool();  // Drain(0)

  void Start();
  // Wakes idle workers after a job was queued.
  void Notify();
  // Sets the cancel flag of a job running in this process; false when it is not running here.
  bool Cancel(const std::string& job_id);
  // Stops taking jobs, waits up to `timeout_s` for running ones, then interrupts the rest and
  // hands them back to the queue (their attempt is not counted). Returns the requeued count.
  int Drain(double timeout_s);

  int busy() const { return busy_.load(); }
  int size() const { return options_.num_workers; }

 private:
  struct RunningJob {
    std::atomic<bool> cancel{false};
    std::atomic<bool> interrupt{false};
  };

  void WorkerLoop();
  void RunJob(const storage::JobRecord& job);
  void WaitForWork(uint64_t seen_generation);

  storage::JobStore& store_;
  const storage::DataDir& data_dir_;
  Metrics& metrics_;
  WorkerPoolOptions options_;
  std::vector<std::thread> threads_;
  std::atomic<int> busy_{0};

  std::mutex mutex_;
  std::condition_variable wake_;
  uint64_t generation_ = 0;  // bumped by Notify(); a worker waits only if it has not changed
  bool stopping_ = false;
  std::map<std::string, std::shared_ptr<RunningJob>> running_;
};

}  // namespace omnirig::server
