#pragma once
// Live slam jobs (api/live_slam.h) in the serving process: each runs on a thread of its own,
// outside the worker pool (a robot's job must not wait behind queued batch jobs, and two robots
// must both advance), fed by the frames route through its one-slot mailbox. The job is created
// already claimed by this process (JobStore::CreateClaimedJob), so no worker anywhere takes it
// from the queue; its lease is renewed here. When this process stops (drain) or dies, the job
// goes back to the queue (requeued, or its lease expires) and a worker runs it again as a batch
// slam job over the frames its dataset holds.
//
// Routes (routes_live.cc): POST /api/v1/jobs with a live slam job's params (CreateLiveJob, from
// the jobs route), POST /api/v1/jobs/{id}/frames, POST /api/v1/jobs/{id}/finish, and the
// running job's trajectory.json and map.ply, and with "dense_map" occupancy.pgm and
// occupancy.yaml, through the artifacts route (ServeArtifact); each refresh of them is an
// `artifacts` event of the job ({"job", "artifacts": [names], ...}).

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

#include "api/live_slam.h"
#include "server/http.h"
#include "storage/records.h"

namespace omnirig::server {

struct ServiceState;

// One live job running here.
struct LiveJob {
  storage::JobRecord record;  // as created (claimed)
  StereoRig rig;
  api::LiveMailbox mailbox;
  // Serialises the frames of the job: the stamp order check, the files' storage and the hand-
  // over to the mailbox happen for one frame at a time.
  std::mutex frames_mutex;
  std::optional<double> last_stamp_s;
  std::string last_name;
  std::atomic<bool> cancel{false};
  std::atomic<bool> interrupt{false};
  std::atomic<bool> ended{false};  // the job's run returned: frames get 409
  std::atomic<bool> done{false};   // the thread's last step: it can be joined
  std::thread thread;
};

class LiveJobs {
 public:
  explicit LiveJobs(ServiceState& state);
  ~LiveJobs();  // Drain(0)
  LiveJobs(const LiveJobs&) = delete;
  LiveJobs& operator=(const LiveJobs&) = delete;

  // Creates the job (running, claimed by this process) and starts its thread. Joins and forgets
  // the jobs whose threads are done: a thread never joined keeps its stack for as long as the
  // process runs (a day of robots' runs is hundreds of them).
  storage::JobRecord Start(const std::string& dataset_id, const nlohmann::json& params,
                           const StereoRig& rig);
  // The live job `id` started by this process (running, or ended and not yet forgotten), or
  // nullptr.
  std::shared_ptr<LiveJob> Find(const std::string& id);
  // The running job's snapshot files (trajectory.json, map.ply, occupancy.pgm, occupancy.yaml)
  // from its attempt folder; false when `id` is not a live job running here or has no such
  // file yet.
  bool ServeArtifact(const std::string& id, const std::string& name, HttpResponse& response);
  // Interrupts the running live jobs and waits for their threads: each goes back to the queue
  // (a worker runs it again as a batch job over its frames). Returns how many.
  int Drain();

 private:
  void Run(const std::shared_ptr<LiveJob>& job);
  void RenewLeases();

  ServiceState& state_;
  std::mutex mutex_;
  std::map<std::string, std::shared_ptr<LiveJob>> jobs_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::thread renew_thread_;
};

// POST /api/v1/jobs for a live slam job ({"type": "slam", "params": {"live": true, ...}}):
// answers it and returns true; false (nothing done) for any other job.
bool CreateLiveJob(ServiceState& state, const HttpRequest& request, HttpResponse& response);
void AddLiveRoutes(HttpServer& http, ServiceState& state);

}  // namespace omnirig::server
