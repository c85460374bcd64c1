#pragma once
// The record store behind the service, as an interface: SQLite on one machine
// (sqlite_job_store.h) or PostgreSQL shared by workers on several machines
// (postgres_job_store.h), with nothing above storage/ changing. Every state change is one
// committed transaction. Methods that change a job's state check the state they expect inside
// that transaction and return false (or nullopt) when another actor got there first.
//
// Leases: a claim gives the job to one worker with a fresh lease token and an expiry; the
// worker's heartbeat renews it while the job runs. A job whose lease expired (its worker was
// killed, stopped or cut off) is queued again with its attempt counted, or failed after the
// maximum number of attempts (RecoverExpiredLeases). The worker's end of the job (FinishJob,
// RequeueJob) is accepted only while its token still matches, so a worker that lost its lease
// never overwrites the outcome of the run that took the job over.

#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "storage/records.h"

namespace omnirig::storage {

// The store cannot be reached right now (PostgreSQL stopped, restarting after a crash, or cut
// off): the call changed nothing it reports, and the same call may succeed once the database is
// back. The API answers 503 with Retry-After; workers wait and try again.
class StoreUnavailable : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The disk holding the store is full: the call's transaction was rolled back. The API answers
// 507.
class StoreFull : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class JobStore {
 public:
  virtual ~JobStore() = default;

  // Datasets and images.
  virtual DatasetRecord CreateDataset(const std::string& name) = 0;
  virtual std::vector<DatasetRecord> ListDatasets() = 0;
  virtual std::optional<DatasetRecord> GetDataset(const std::string& id) = 0;
  // Removes the dataset and its image records; false when it does not exist.
  virtual bool DeleteDataset(const std::string& id) = 0;
  // Inserts or replaces the image record (idempotent uploads).
  virtual void PutImage(const std::string& dataset_id, const ImageRecord& image) = 0;
  // PutImage for each record in order (a later one replaces an earlier one of the same name), in
  // one transaction: all are stored or, when it throws, none (a multipart upload's files).
  virtual void PutImages(const std::string& dataset_id,
                         const std::vector<ImageRecord>& images) = 0;
  virtual bool DeleteImage(const std::string& dataset_id, const std::string& name) = 0;
  virtual std::vector<ImageRecord> ListImages(const std::string& dataset_id) = 0;  // by name
  virtual std::optional<ImageRecord> GetImage(const std::string& dataset_id,
                                              const std::string& name) = 0;

  // Jobs.
  virtual JobRecord CreateJob(const std::string& type, const std::string& dataset_id,
                              const std::string& params) = 0;
  virtual std::optional<JobRecord> GetJob(const std::string& id) = 0;
  virtual std::vector<JobRecord> ListJobs(const JobFilter& filter) = 0;  // newest first
  // Takes the oldest queued job: running, started_at now, attempts + 1, leased to
  // `request.worker_id` with a new lease token until now + `request.lease_s`.
  virtual std::optional<JobRecord> ClaimNextJob(const ClaimRequest& request) = 0;
  // A new job claimed at once by `request.worker_id` (running, attempts 1, leased as
  // ClaimNextJob leases): a job that only this process can run (a live job, fed by its HTTP
  // routes), which no other worker may take from the queue. Its lease expiring (the process
  // died) queues it like any other.
  virtual JobRecord CreateClaimedJob(const std::string& type, const std::string& dataset_id,
                                     const std::string& params, const ClaimRequest& request) = 0;
  // Extends a running job's lease to now + `lease_s`; false when the job is no longer running
  // under `lease_token` (the lease was lost: the worker must stop the job).
  virtual bool RenewLease(const std::string& id, const std::string& lease_token,
                          double lease_s) = 0;
  virtual void UpdateProgress(const std::string& id, const JobProgress& progress) = 0;
  // Queued -> canceled at once; running -> cancel_requested (the worker stops it). Returns the
  // state after the call, nullopt when the job does not exist.
  virtual std::optional<JobState> RequestCancel(const std::string& id) = 0;
  // Running under `lease_token` -> the outcome's state, with result and artifacts; false (and
  // nothing written) when the job is not running or its lease went to another claim.
  virtual bool FinishJob(const std::string& id, const std::string& lease_token,
                         const JobOutcome& outcome) = 0;
  // Running under `lease_token` -> queued (a drained worker hands the job back); the attempt is
  // not counted.
  virtual bool RequeueJob(const std::string& id, const std::string& lease_token) = 0;
  // Failed or canceled -> queued with attempts, error, result and artifacts cleared.
  virtual bool RetryJob(const std::string& id) = 0;
  // Removes a job that is not running, with its artifact records.
  virtual bool DeleteJob(const std::string& id) = 0;
  virtual std::optional<std::string> GetResult(const std::string& id) = 0;
  virtual std::vector<ArtifactRecord> ListArtifacts(const std::string& job_id) = 0;
  // Jobs left running by a crash: canceled when a cancel was requested, failed with code
  // "interrupted" once `max_attempts` runs were started, queued again otherwise.
  // Every running job counts as interrupted: only for a store no other process uses (SQLite
  // at start-up).
  virtual RecoveryReport RecoverInterruptedJobs(int max_attempts) = 0;
  // The same for running jobs whose lease expired, whoever holds the store: any worker may call
  // it at any time.
  virtual RecoveryReport RecoverExpiredLeases(int max_attempts) = 0;
  virtual std::map<JobState, int64_t> CountJobsByState() = 0;
  // Jobs queued or running on the dataset.
  virtual int64_t CountActiveJobs(const std::string& dataset_id) = 0;

  // Store copy (`omnirig store copy`): records inserted as they are, ids, states and times kept.
  // A record whose id already exists is left alone (a copy that stopped half-way can be run
  // again); returns false then.
  virtual bool ImportDataset(const DatasetRecord& dataset) = 0;
  virtual bool ImportJob(const JobRecord& job, const std::optional<std::string>& result,
                         const std::vector<ArtifactRecord>& artifacts) = 0;

  // Workers: a heartbeat records the worker as alive now with its running jobs (upsert by id).
  virtual void RecordHeartbeat(const WorkerRecord& worker) = 0;
  // Workers whose last heartbeat is at most `seen_within_s` old, by id.
  virtual std::vector<WorkerRecord> ListWorkers(double seen_within_s) = 0;

  // Whether WaitForQueueChange can wake on jobs queued by other processes (PostgreSQL NOTIFY).
  virtual bool NotifiesQueueChanges() const { return false; }
  // Blocks up to `timeout_s` until a job may have been queued by any process; true when woken
  // by a notification, false on timeout (or when the store cannot notify).
  virtual bool WaitForQueueChange(double /*timeout_s*/) { return false; }

  // "ok", or the database's list of problems.
  virtual std::string IntegrityCheck() = 0;
};

}  // namespace omnirig::storage
