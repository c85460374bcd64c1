#pragma once
// JobStore on one SQLite file in WAL mode: one writer connection (writes are serialised by
// SQLite anyway) and a small pool of reader connections, so status polls never wait behind a
// commit's fsync. The schema is versioned with PRAGMA user_version and migrated on open.

#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "storage/job_store.h"
#include "storage/sqlite_db.h"

namespace omnirig::storage {

class SqliteJobStore : public JobStore {
 public:
  // Opens or creates the database and applies pending migrations.
  explicit SqliteJobStore(const std::string& path, int num_readers = 4);
  ~SqliteJobStore() override;

  // The schema version this build writes (user_version after migration).
  static int SchemaVersion();

  DatasetRecord CreateDataset(const std::string& name) override;
  std::vector<DatasetRecord> ListDatasets() override;
  std::optional<DatasetRecord> GetDataset(const std::string& id) override;
  bool DeleteDataset(const std::string& id) override;
  void PutImage(const std::string& dataset_id, const ImageRecord& image) override;
  void PutImages(const std::string& dataset_id, const std::vector<ImageRecord>& images) override;
  bool DeleteImage(const std::string& dataset_id, const std::string& name) override;
  std::vector<ImageRecord> ListImages(const std::string& dataset_id) override;
  std::optional<ImageRecord> GetImage(const std::string& dataset_id,
                                      const std::string& name) override;

  JobRecord CreateJob(const std::string& type, const std::string& dataset_id,
                      const std::string& params) override;
  std::optional<JobRecord> GetJob(const std::string& id) override;
  std::vector<JobRecord> ListJobs(const JobFilter& filter) override;
  using JobStore::ClaimNextJob;
  std::optional<JobRecord> ClaimNextJob(const ClaimRequest& request) override;
  bool RenewLease(const std::string& id, const std::string& lease_token, double lease_s) override;
  void UpdateProgress(const std::string& id, const JobProgress& progress) override;
  std::optional<JobState> RequestCancel(const std::string& id) override;
  bool FinishJob(const std::string& id, const std::string& lease_token,
                 const JobOutcome& outcome) override;
  bool RequeueJob(const std::string& id, const std::string& lease_token) override;
  bool RetryJob(const std::string& id) override;
  bool DeleteJob(const std::string& id) override;
  std::optional<std::string> GetResult(const std::string& id) override;
  std::vector<ArtifactRecord> ListArtifacts(const std::string& job_id) override;
  RecoveryReport RecoverInterruptedJobs(int max_attempts) override;
  RecoveryReport RecoverExpiredLeases(int max_attempts) override;
  std::map<JobState, int64_t> CountJobsByState() override;
  int64_t CountActiveJobs(const std::string& dataset_id) override;
  bool ImportDataset(const DatasetRecord& dataset) override;
  bool ImportJob(const JobRecord& job, const std::optional<std::string>& result,
                 const std::vector<ArtifactRecord>& artifacts) override;
  void RecordHeartbeat(const WorkerRecord& worker) override;
  std::vector<WorkerRecord> ListWorkers(double seen_within_s) override;
  std::string IntegrityCheck() override;

 private:
  // A reader connection borrowed from the pool for one call.
  class ReaderLease;
  ReaderLease Reader();
  void Migrate();
  // Requeues, fails or cancels the running jobs (those whose lease ended before `expired_before`
  // when given).
  RecoveryReport RecoverRunning(int max_attempts, std::optional<double> expired_before);

  std::string path_;
  std::mutex writer_mutex_;
  std::unique_ptr<Connection> writer_;
  std::mutex readers_mutex_;
  std::condition_variable readers_available_;
  std::vector<std::unique_ptr<Connection>> idle_readers_;
};

}  // namespace omnirig::storage
