#include "server/live_jobs.h"

#include <chrono>
#include <filesystem>
#include <iostream>
#include <set>
#include <vector>

#include "server/job_runner.h"
#include "server/service.h"
#include "storage/image_header.h"

namespace omnirig::server {

LiveJobs::LiveJobs(ServiceState& state) : state_(state) {
  renew_thread_ = std::thread([this] { RenewLeases(); });
}

LiveJobs::~LiveJobs() {
  Drain();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  renew_thread_.join();
}

storage::JobRecord LiveJobs::Start(const std::string& dataset_id, const nlohmann::json& params,
                                   const StereoRig& rig) {
  std::vector<std::shared_ptr<LiveJob>> done;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto it = jobs_.begin(); it != jobs_.end();) {
      if (!it->second->done) {
        ++it;
        continue;
      }
      done.push_back(it->second);
      it = jobs_.erase(it);
    }
  }
  for (const auto& ended : done) ended->thread.join();
  auto job = std::make_shared<LiveJob>();
  job->rig = rig;
  job->record = state_.store->CreateClaimedJob(
      "slam", dataset_id, params.dump(),
      storage::ClaimRequest{state_.workers->worker_id(), state_.options.workers.lease_s});
  {
    std::lock_guard<std::mutex> lock(mutex_);
    // Started while the service drains: the job goes straight back to the queue.
    if (stopping_) job->interrupt = true;
    jobs_[job->record.id] = job;
    job->thread = std::thread([this, job] { Run(job); });
  }
  return job->record;
}

std::shared_ptr<LiveJob> LiveJobs::Find(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = jobs_.find(id);
  return it == jobs_.end() ? nullptr : it->second;
}

bool LiveJobs::ServeArtifact(const std::string& id, const std::string& name,
                             HttpResponse& response) {
  const std::shared_ptr<LiveJob> job = Find(id);
  if (!job || job->ended) return false;
  // The files the job refreshes while it runs (api/live_publisher.h).
  static const std::set<std::string> kLiveFiles = {"trajectory.json", "map.ply", "occupancy.pgm",
                                                   "occupancy.yaml"};
  if (kLiveFiles.count(name) == 0) return false;
  const std::filesystem::path path = state_.data_dir->AttemptDir(id, job->record.attempts) / name;
  std::error_code error;
  const auto size = std::filesystem::file_size(path, error);
  if (error) return false;
  // The snapshot is replaced by a rename: the file opened here stays whole.
  response.headers.emplace("Cache-Control", "no-store");
  response.content_type = storage::ContentTypeForName(name);
  response.file = path;
  response.file_size = static_cast<int64_t>(size);
  return true;
}

void LiveJobs::Run(const std::shared_ptr<LiveJob>& job) {
  JobRunOptions options;
  options.num_threads = state_.options.workers.threads_per_job;
  options.progress_interval_s = state_.options.workers.progress_interval_s;
  JobEvents* events = state_.events.get();
  options.on_progress = [events](const std::string& id) { events->Changed(id); };
  const std::string id = job->record.id;
  // The job's `frame` and `artifacts` events (each with "job": its id).
  const auto publish = [events, id](const std::string& type) {
    return [events, id, type](const nlohmann::json& event) {
      nlohmann::json data = event;
      data["job"] = id;
      events->Publish(id, type, data);
    };
  };
  options.run = [job, publish](const nlohmann::json& params, const api::JobContext& context) {
    return api::RunLiveSlam(params, context, job->rig, job->mailbox, publish("frame"),
                            publish("artifacts"));
  };
  events->Changed(id);
  const storage::JobOutcome outcome =
      RunJobAttempt(job->record, *state_.store, *state_.data_dir, state_.job_types, options,
                    {&job->cancel, &job->interrupt});
  // A run that ended early (canceled, failed) has not closed the mailbox: a frame waiting in it
  // gets its answer here.
  job->mailbox.Close({409,
                      {{"error",
                        {{"code", "job_finished"},
                         {"message", "live job " + id + " has ended: it takes no more frames"},
                         {"details", {{"job", id}}}}}}});
  job->ended = true;
  const bool handed_back =
      outcome.state == storage::JobState::kCanceled && job->interrupt && !job->cancel;
  try {
    const auto current = state_.store->GetJob(id);
    if (handed_back && !(current && current->cancel_requested)) {
      if (state_.store->RequeueJob(id, job->record.lease_token)) {
        RemoveOtherAttempts(*state_.data_dir, job->record);
      }
      state_.workers->Notify();
    } else if (state_.store->FinishJob(id, job->record.lease_token, outcome)) {
      RemoveOtherAttempts(*state_.data_dir, job->record);
    } else {
      std::cerr << "omnirig: the end of live job " << id
                << " was refused: its lease went to another run" << std::endl;
    }
  } catch (const std::exception& e) {
    // The job stays running in the store; its lease expires and it is queued again.
    std::cerr << "omnirig: cannot record the end of live job " << id << ": " << e.what()
              << std::endl;
  }
  events->Changed(id);
  job->done = true;
}

void LiveJobs::RenewLeases() {
  const double lease_s = state_.options.workers.lease_s;
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stopping_) {
    wake_.wait_for(lock, std::chrono::duration<double>(lease_s / 3), [this] { return stopping_; });
    std::vector<std::shared_ptr<LiveJob>> running;
    for (const auto& [id, job] : jobs_) {
      if (!job->ended) running.push_back(job);
    }
    lock.unlock();
    for (const auto& job : running) {
      try {
        if (!state_.store->RenewLease(job->record.id, job->record.lease_token, lease_s)) {
          // Another run owns the job now (this process was stopped past its lease).
          job->interrupt = true;
        }
      } catch (const std::exception& e) {
        std::cerr << "omnirig: cannot renew the lease of live job " << job->record.id << ": "
                  << e.what() << std::endl;
      }
    }
    lock.lock();
  }
}

int LiveJobs::Drain() {
  std::vector<std::shared_ptr<LiveJob>> all;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& [id, job] : jobs_) all.push_back(job);
  }
  int requeued = 0;
  for (const auto& job : all) {
    if (!job->ended) {
      job->interrupt = true;
      ++requeued;
    }
    if (job->thread.joinable()) job->thread.join();
  }
  return requeued;
}

}  // namespace omnirig::server
