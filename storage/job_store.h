#pragma once
// The record store behind the service, as an interface: SQLite on one machine today
// (sqlite_job_store.h); a PostgreSQL implementation lets workers on several machines share
// one queue later, with nothing above storage/ changing. Every state change is one committed
// transaction. Methods that change a job's state check the state they expect inside that
// transaction and return false (or nullopt) when another actor got there first.

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "storage/records.h"

namespace omnirig::storage {

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
  // Takes the oldest queued job: running, started_at now, attempts + 1.
  virtual std::optional<JobRecord> ClaimNextJob() = 0;
  virtual void UpdateProgress(const std::string& id, const JobProgress& progress) = 0;
  // Queued -> canceled at once; running -> cancel_requested (the worker stops it). Returns the
  // state after the call, nullopt when the job does not exist.
  virtual std::optional<JobState> RequestCancel(const std::string& id) = 0;
  // Running -> the outcome's state, with result and artifacts.
  virtual bool FinishJob(const std::string& id, const JobOutcome& outcome) = 0;
  // Running -> queued (a drained server hands the job back); the attempt is not counted.
  virtual bool RequeueJob(const std::string& id) = 0;
  // Failed or canceled -> queued with attempts, error, result and artifacts cleared.
  virtual bool RetryJob(const std::string& id) = 0;
  // Removes a job that is not running, with its artifact records.
  virtual bool DeleteJob(const std::string& id) = 0;
  virtual std::optional<std::string> GetResult(const std::string& id) = 0;
  virtual std::vector<ArtifactRecord> ListArtifacts(const std::string& job_id) = 0;
  // Jobs left running by a crash: canceled when a cancel was requested, failed with code
  // "interrupted" once `max_attempts` runs were started, queued again otherwise.
  virtual RecoveryReport RecoverInterruptedJobs(int max_attempts) = 0;
  virtual std::map<JobState, int64_t> CountJobsByState() = 0;
  // Jobs queued or running on the dataset.
  virtual int64_t CountActiveJobs(const std::string& dataset_id) = 0;

  // "ok", or SQLite's list of problems.
  virtual std::string IntegrityCheck() = 0;
};

}  // namespace omnirig::storage
