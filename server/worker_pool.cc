#include "server/worker_pool.h"

#include <sched.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <chrono>
#include <cstring>
#include <iostream>

#include "engine/util/check.h"
#include "server/job_runner.h"
#include "server/log_line.h"

namespace omnirig::server {

void WorkerPoolOptions::Check() const {
  OMNIRIG_CHECK(num_workers >= 0, "--workers must not be negative, got " << num_workers);
  OMNIRIG_CHECK(threads_per_job >= 1, "threads per job must be at least 1");
  OMNIRIG_CHECK(progress_interval_s >= 0 && idle_poll_s > 0, "invalid worker intervals");
  OMNIRIG_CHECK(lease_s > 0, "--lease-seconds must be positive, got " << lease_s);
  OMNIRIG_CHECK(max_attempts >= 1, "--max-attempts must be at least 1");
  OMNIRIG_CHECK(min_free_bytes >= 0, "--min-free-mb must not be negative");
}

namespace {

// "HOST:PID": unique among live processes sharing a store.
std::string DefaultWorkerId() {
  char host[256] = {};
  if (::gethostname(host, sizeof(host) - 1) != 0) std::strcpy(host, "localhost");
  return std::string(host) + ":" + std::to_string(::getpid());
}

}  // namespace

WorkerPool::WorkerPool(storage::JobStore& store, const storage::DataDir& data_dir,
                       const api::JobTypes& job_types, Metrics& metrics,
                       const WorkerPoolOptions& options)
    : store_(store),
      data_dir_(data_dir),
      job_types_(job_types),
      metrics_(metrics),
      options_(options) {
  options_.Check();
  if (options_.worker_id.empty()) options_.worker_id = DefaultWorkerId();
}

WorkerPool::~WorkerPool() { Drain(0); }

void WorkerPool::Start() {
  if (options_.num_workers == 0) return;
  started_at_ = storage::NowSeconds();
  for (int i = 0; i < options_.num_workers; ++i) threads_.emplace_back([this] { WorkerLoop(); });
  heartbeat_thread_ = std::thread([this] { HeartbeatLoop(); });
  if (store_.NotifiesQueueChanges()) listener_thread_ = std::thread([this] { ListenLoop(); });
}

void WorkerPool::Notify() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++generation_;
  wake_.notify_all();
}

bool WorkerPool::Cancel(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = running_.find(job_id);
  if (it == running_.end()) return false;
  it->second->cancel = true;
  return true;
}

void WorkerPool::StopClaiming() {
  std::lock_guard<std::mutex> lock(mutex_);
  stopping_ = true;
  wake_.notify_all();
}

int WorkerPool::Drain(double timeout_s) {
  StopClaiming();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  int interrupted = 0;
  {
    std::unique_lock<std::mutex> lock(mutex_);
    wake_.wait_until(lock, deadline, [this] { return running_.empty(); });
    for (auto& [id, job] : running_) {
      job->interrupt = true;
      ++interrupted;
    }
  }
  for (std::thread& thread : threads_) {
    if (thread.joinable()) thread.join();
  }
  threads_.clear();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    background_stopping_ = true;
    wake_.notify_all();
  }
  if (heartbeat_thread_.joinable()) heartbeat_thread_.join();
  if (listener_thread_.joinable()) listener_thread_.join();
  return interrupted;
}

void WorkerPool::HeartbeatLoop() {
  const auto interval = std::chrono::duration<double>(options_.lease_s / 3);
  std::unique_lock<std::mutex> lock(mutex_);
  while (!background_stopping_) {
    lock.unlock();
    Heartbeat();
    lock.lock();
    wake_.wait_for(lock, interval, [this] { return background_stopping_; });
  }
}

void WorkerPool::Heartbeat() {
  std::map<std::string, std::shared_ptr<RunningJob>> running;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    running = running_;
  }
  storage::WorkerRecord self{options_.worker_id, started_at_, 0, {}};
  for (const auto& [id, job] : running) {
    if (job->ending) continue;
    try {
      // Refused while `ending` is still false: our own end had not started, the lease is lost.
      if (!store_.RenewLease(id, job->lease_token, options_.lease_s) && !job->ending) {
        // Stopped or cut off past the lease: the job was re-queued and may run elsewhere now.
        job->lease_lost = true;
        job->interrupt = true;
        std::cerr << "omnirig: lost the lease of job " << id << "; stopping it" << std::endl;
        continue;
      }
    } catch (const std::exception& e) {
      std::cerr << "omnirig: cannot renew the lease of job " << id << ": " << e.what() << std::endl;
    }
    self.running_jobs.push_back(id);
  }
  try {
    store_.RecordHeartbeat(self);
    const storage::RecoveryReport recovered = store_.RecoverExpiredLeases(options_.max_attempts);
    LogRecovery(store_, recovered, "lease_expired");
    if (!recovered.requeued.empty()) Notify();
  } catch (const std::exception& e) {
    std::cerr << "omnirig: heartbeat not recorded: " << e.what() << std::endl;
  }
}

void WorkerPool::ListenLoop() {
  while (true) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (background_stopping_) return;
    }
    bool woken = false;
    try {
      woken = store_.WaitForQueueChange(0.25);  // short: Drain() waits for this thread
    } catch (const std::exception& e) {
      std::cerr << "omnirig: queue notifications unavailable: " << e.what() << std::endl;
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait_for(lock, std::chrono::duration<double>(options_.idle_poll_s),
                     [this] { return background_stopping_; });
    }
    if (woken) Notify();
  }
}

void WorkerPool::WaitForWork(uint64_t seen_generation) {
  std::unique_lock<std::mutex> lock(mutex_);
  wake_.wait_for(lock, std::chrono::duration<double>(options_.idle_poll_s),
                 [&] { return stopping_ || generation_ != seen_generation; });
}

void WorkerPool::WorkerLoop() {
  // Optional: workers (and the solver threads they start, which inherit it) may yield the CPU.
  // Linux nice is per thread.
  if (options_.nice > 0) ::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), options_.nice);
  if (options_.idle_scheduling) {
    sched_param param{};
    param.sched_priority = 0;
    if (::sched_setscheduler(0, SCHED_IDLE, &param) != 0) {  // 0: this thread (Linux)
      std::cerr << "omnirig: SCHED_IDLE for a worker thread refused: " << std::strerror(errno)
                << std::endl;
    }
  }
  while (true) {
    uint64_t generation;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stopping_) return;
      generation = generation_;
    }
    std::optional<storage::JobRecord> job;
    try {
      job = store_.ClaimNextJob(storage::ClaimRequest{options_.worker_id, options_.lease_s});
    } catch (const std::exception& e) {
      std::cerr << "omnirig: cannot claim a job: " << e.what() << std::endl;
    }
    if (job) {
      RunJob(*job);
    } else {
      WaitForWork(generation);
    }
  }
}

bool WorkerPool::RecordEnd(const storage::JobRecord& job, RunningJob& running, bool hand_back,
                           const storage::JobOutcome& outcome) {
  if (running.lease_lost) {
    // Another worker owns the job now; FinishJob would be refused anyway.
    std::cerr << "omnirig: job " << job.id << " stopped after losing its lease" << std::endl;
    return false;
  }
  double pause_s = 0.1;
  while (true) {
    try {
      const bool accepted = hand_back ? store_.RequeueJob(job.id, job.lease_token)
                                      : store_.FinishJob(job.id, job.lease_token, outcome);
      if (accepted) {
        RemoveOtherAttempts(data_dir_, job);
      } else if (!hand_back) {
        // The lease ran out before the heartbeat saw it (or the job is no longer running).
        std::cerr << "omnirig: the end of job " << job.id
                  << " was refused: its lease went to another run" << std::endl;
      }
      return accepted;
    } catch (const std::exception& e) {
      std::cerr << "omnirig: cannot record the end of job " << job.id << " yet: " << e.what()
                << std::endl;
    }
    std::unique_lock<std::mutex> lock(mutex_);
    if (wake_.wait_for(lock, std::chrono::duration<double>(pause_s), [this] { return stopping_; })) {
      // Stopping: the job stays `running` in the store; its lease expires and it is re-queued.
      std::cerr << "omnirig: gave up recording the end of job " << job.id << " (stopping)"
                << std::endl;
      return false;
    }
    pause_s = std::min(2 * pause_s, std::max(0.1, options_.lease_s / 6));
  }
}

void WorkerPool::RunJob(const storage::JobRecord& job) {
  auto running = std::make_shared<RunningJob>();
  running->lease_token = job.lease_token;
  running->cancel = job.cancel_requested;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    running_[job.id] = running;
    // Claimed while Drain() began: hand it straight back rather than run it to the end.
    if (stopping_) running->interrupt = true;
  }
  ++busy_;
  LogJobState(job, {{"worker", options_.worker_id}});
  if (options_.on_job_changed) options_.on_job_changed(job.id);
  const auto start = std::chrono::steady_clock::now();
  JobRunOptions run_options;
  run_options.num_threads = options_.threads_per_job;
  run_options.progress_interval_s = options_.progress_interval_s;
  run_options.on_progress = options_.on_job_changed;
  run_options.min_free_bytes = options_.min_free_bytes;
  const storage::JobOutcome outcome =
      RunJobAttempt(job, store_, data_dir_, job_types_, run_options,
                    JobRunFlags{&running->cancel, &running->interrupt});
  bool handed_back =
      outcome.state == storage::JobState::kCanceled && running->interrupt && !running->cancel;
  if (handed_back) {
    // A drain interrupted it, unless a cancel was also written to the store by another process.
    try {
      const auto current = store_.GetJob(job.id);
      handed_back = !(current && current->cancel_requested);
    } catch (const std::exception&) {
    }
  }
  // The store was away during the run (RunJobAttempt): queued again, not failed.
  handed_back = handed_back || outcome.state == storage::JobState::kQueued;
  running->ending = true;
  if (RecordEnd(job, *running, handed_back, outcome)) {
    if (handed_back) {
      LogJobState(job.id, job.type, "queued", job.attempts,
                  {{"reason", outcome.state == storage::JobState::kQueued ? "store_unavailable"
                                                                         : "drain"}});
    } else {
      const double duration_s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      metrics_.ObserveJobDuration(job.type, storage::JobStateName(outcome.state), duration_s);
      char duration[32];
      std::snprintf(duration, sizeof(duration), "%.3f", duration_s);
      LogFields detail = {{"duration_s", duration}};
      if (outcome.error) detail.push_back({"error_code", outcome.error->code});
      LogJobState(job.id, job.type, storage::JobStateName(outcome.state), job.attempts, detail);
    }
  }
  if (options_.on_job_changed) options_.on_job_changed(job.id);
  --busy_;
  std::lock_guard<std::mutex> lock(mutex_);
  running_.erase(job.id);
  wake_.notify_all();
}

}  // namespace omnirig::server
