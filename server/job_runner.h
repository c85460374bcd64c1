#pragma once
// Runs one claimed job attempt: builds its JobContext, calls the job type, and turns the
// outcome (result, Cancelled, InvalidArgument, any other exception) into a JobOutcome with
// artifacts. Separate from the pool so the pool only schedules.

#include <atomic>
#include <functional>
#include <string>

#include "api/job_types.h"
#include "storage/data_dir.h"
#include "storage/job_store.h"

namespace omnirig::server {

struct JobRunFlags {
  const std::atomic<bool>* cancel = nullptr;     // user cancel
  const std::atomic<bool>* interrupt = nullptr;  // server draining
};

struct JobRunOptions {
  int num_threads = 1;
  double progress_interval_s = 0.2;
  // How often a running job re-reads its cancel flag from the store, to see a cancel written
  // by another process; 0 turns the check off.
  double store_cancel_check_s = 0.2;
  // Called after each progress write with the job's id (e.g. JobEvents::Changed); may be empty.
  std::function<void(const std::string&)> on_progress;
  // Free space to keep on the data folder's disk: a run that leaves less fails with
  // "disk_full" (its outputs removed, so the store can record that); 0: only a write that
  // failed for want of space does.
  int64_t min_free_bytes = 0;
  // How often a running job reads the disk's free space.
  double disk_check_s = 0.2;
  // Runs the job instead of its type's `run` (a live job, fed by this process's HTTP routes);
  // empty: the type's.
  std::function<nlohmann::json(const nlohmann::json& params, const api::JobContext& context)> run;
};

// Runs `job` (already claimed: state running, attempts counted) with its type from
// `job_types`. Never throws. An outcome in state kQueued means the store could not be reached
// during the run (StoreUnavailable): the job is to be handed back to the queue, not failed.
storage::JobOutcome RunJobAttempt(const storage::JobRecord& job, storage::JobStore& store,
                                  const storage::DataDir& data_dir, const api::JobTypes& job_types,
                                  const JobRunOptions& options, const JobRunFlags& flags);

// Removes the output folders of the job's other attempts (interrupted by a crash, a drain or a
// lost lease): they hold nothing the records point to. Called only once the store accepted this
// attempt's end, so a worker that lost its lease never removes the folder of the run that took
// its job over.
void RemoveOtherAttempts(const storage::DataDir& data_dir, const storage::JobRecord& job);

}  // namespace omnirig::server
