#include "storage/sqlite_job_store.h"

namespace omnirig::storage {
namespace {

// Schema migrations, applied in order; user_version counts the applied ones. Never edit a
// shipped entry: append a new one.
const char* const kMigrations[] = {
    R"sql(
CREATE TABLE datasets(
  id TEXT PRIMARY KEY,
  name TEXT NOT NULL,
  created_at REAL NOT NULL);
CREATE TABLE images(
  dataset_id TEXT NOT NULL REFERENCES datasets(id) ON DELETE CASCADE,
  name TEXT NOT NULL,
  size INTEGER NOT NULL,
  sha256 TEXT NOT NULL,
  width INTEGER NOT NULL,
  height INTEGER NOT NULL,
  content_type TEXT NOT NULL,
  PRIMARY KEY(dataset_id, name));
CREATE TABLE jobs(
  id TEXT PRIMARY KEY,
  type TEXT NOT NULL,
  dataset_id TEXT NOT NULL,
  params TEXT NOT NULL,
  state TEXT NOT NULL CHECK(state IN ('queued','running','succeeded','failed','canceled')),
  progress_fraction REAL NOT NULL DEFAULT 0,
  progress_stage TEXT NOT NULL DEFAULT '',
  progress_message TEXT NOT NULL DEFAULT '',
  eta_s REAL,
  created_at REAL NOT NULL,
  queued_at REAL NOT NULL,
  started_at REAL,
  finished_at REAL,
  attempts INTEGER NOT NULL DEFAULT 0,
  error_code TEXT,
  error_message TEXT,
  result TEXT,
  cancel_requested INTEGER NOT NULL DEFAULT 0);
CREATE INDEX jobs_by_state ON jobs(state, queued_at);
CREATE INDEX jobs_by_dataset ON jobs(dataset_id);
CREATE TABLE artifacts(
  job_id TEXT NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
  name TEXT NOT NULL,
  path TEXT NOT NULL,
  size INTEGER NOT NULL,
  sha256 TEXT NOT NULL,
  content_type TEXT NOT NULL,
  PRIMARY KEY(job_id, name));
)sql",
    // 2: leases (who runs a job, until when) and worker heartbeats.
    R"sql(
ALTER TABLE jobs ADD COLUMN worker_id TEXT NOT NULL DEFAULT '';
ALTER TABLE jobs ADD COLUMN lease_token TEXT NOT NULL DEFAULT '';
ALTER TABLE jobs ADD COLUMN lease_expires_at REAL;
CREATE TABLE workers(
  id TEXT PRIMARY KEY,
  started_at REAL NOT NULL,
  last_seen_at REAL NOT NULL,
  running_jobs TEXT NOT NULL DEFAULT '');
)sql",
};

constexpr char kJobColumns[] =
    "id, type, dataset_id, params, state, progress_fraction, progress_stage, progress_message, "
    "eta_s, created_at, started_at, finished_at, attempts, error_code, error_message, "
    "cancel_requested, worker_id, lease_token, lease_expires_at";

JobRecord ReadJob(const Statement& row) {
  JobRecord job;
  job.id = row.Text(0);
  job.type = row.Text(1);
  job.dataset_id = row.Text(2);
  job.params = row.Text(3);
  job.state = ParseJobState(row.Text(4)).value_or(JobState::kFailed);
  job.progress = JobProgress{row.Double(5), row.Text(6), row.Text(7), row.OptionalDouble(8)};
  job.created_at = row.Double(9);
  job.started_at = row.OptionalDouble(10);
  job.finished_at = row.OptionalDouble(11);
  job.attempts = static_cast<int>(row.Int(12));
  if (!row.IsNull(13)) job.error = JobError{row.Text(13), row.Text(14)};
  job.cancel_requested = row.Int(15) != 0;
  job.worker_id = row.Text(16);
  job.lease_token = row.Text(17);
  job.lease_expires_at = row.OptionalDouble(18);
  return job;
}

std::optional<JobRecord> SelectJob(Connection& db, const std::string& id) {
  // Built once: the statement cache is keyed by the SQL text (a status poll per lookup).
  static const std::string kSelect =
      std::string("SELECT ") + kJobColumns + " FROM jobs WHERE id = ?";
  Statement select(db, kSelect);
  select.Bind(1, id);
  if (!select.Step()) return std::nullopt;
  return ReadJob(select);
}

DatasetRecord ReadDataset(const Statement& row) {
  return DatasetRecord{row.Text(0), row.Text(1), row.Double(2), row.Int(3), row.Int(4), row.Int(5)};
}

constexpr char kDatasetSelect[] =
    "SELECT d.id, d.name, d.created_at, "
    "COUNT(i.name) - COUNT(CASE WHEN i.content_type LIKE 'video/%' THEN 1 END), "
    "COALESCE(SUM(i.size), 0), COUNT(CASE WHEN i.content_type LIKE 'video/%' THEN 1 END) "
    "FROM datasets d LEFT JOIN images i ON i.dataset_id = d.id ";

}  // namespace

class SqliteJobStore::ReaderLease {
 public:
  ReaderLease(SqliteJobStore& store, std::unique_ptr<Connection> connection)
      : store_(&store), connection_(std::move(connection)) {}
  ReaderLease(ReaderLease&& other) noexcept = default;
  ~ReaderLease() {
    if (!connection_) return;
    std::lock_guard<std::mutex> lock(store_->readers_mutex_);
    store_->idle_readers_.push_back(std::move(connection_));
    store_->readers_available_.notify_one();
  }
  Connection& operator*() { return *connection_; }
  sqlite3* handle() { return connection_->handle(); }

 private:
  SqliteJobStore* store_;
  std::unique_ptr<Connection> connection_;
};

SqliteJobStore::SqliteJobStore(const std::string& path, int num_readers) : path_(path) {
  writer_ = std::make_unique<Connection>(path);
  Migrate();
  for (int i = 0; i < std::max(1, num_readers); ++i) {
    idle_readers_.push_back(std::make_unique<Connection>(path));
  }
}

SqliteJobStore::~SqliteJobStore() = default;

int SqliteJobStore::SchemaVersion() {
  return static_cast<int>(sizeof(kMigrations) / sizeof(kMigrations[0]));
}

SqliteJobStore::ReaderLease SqliteJobStore::Reader() {
  std::unique_lock<std::mutex> lock(readers_mutex_);
  readers_available_.wait(lock, [this] { return !idle_readers_.empty(); });
  std::unique_ptr<Connection> connection = std::move(idle_readers_.back());
  idle_readers_.pop_back();
  return ReaderLease(*this, std::move(connection));
}

void SqliteJobStore::Migrate() {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement version_query(*writer_, "PRAGMA user_version");
  version_query.Step();
  const int version = static_cast<int>(version_query.Int(0));
  if (version > SchemaVersion()) {
    throw SqliteError("database " + path_ + " has schema version " + std::to_string(version) +
                      ", newer than this build's " + std::to_string(SchemaVersion()));
  }
  for (int next = version; next < SchemaVersion(); ++next) {
    Transaction transaction(*writer_);
    writer_->Exec(kMigrations[next]);
    writer_->Exec("PRAGMA user_version = " + std::to_string(next + 1));
    transaction.Commit();
  }
}

DatasetRecord SqliteJobStore::CreateDataset(const std::string& name) {
  DatasetRecord dataset{NewId(), name, NowSeconds(), 0, 0};
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement insert(*writer_, "INSERT INTO datasets(id, name, created_at) VALUES(?,?,?)");
  insert.Bind(1, dataset.id).Bind(2, dataset.name).Bind(3, dataset.created_at).Run();
  return dataset;
}

std::vector<DatasetRecord> SqliteJobStore::ListDatasets() {
  ReaderLease db = Reader();
  Statement select(*db, std::string(kDatasetSelect) + "GROUP BY d.id ORDER BY d.created_at DESC");
  std::vector<DatasetRecord> datasets;
  while (select.Step()) datasets.push_back(ReadDataset(select));
  return datasets;
}

std::optional<DatasetRecord> SqliteJobStore::GetDataset(const std::string& id) {
  ReaderLease db = Reader();
  Statement select(*db, std::string(kDatasetSelect) + "WHERE d.id = ? GROUP BY d.id");
  select.Bind(1, id);
  if (!select.Step()) return std::nullopt;
  return ReadDataset(select);
}

bool SqliteJobStore::DeleteDataset(const std::string& id) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement remove(*writer_, "DELETE FROM datasets WHERE id = ?");
  remove.Bind(1, id).Run();
  return writer_->changes() > 0;
}

void SqliteJobStore::PutImage(const std::string& dataset_id, const ImageRecord& image) {
  PutImages(dataset_id, {image});
}

// One commit (one WAL fsync) for the whole batch instead of one per record.
void SqliteJobStore::PutImages(const std::string& dataset_id,
                               const std::vector<ImageRecord>& images) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Transaction transaction(*writer_);
  for (const ImageRecord& image : images) {
    Statement upsert(*writer_,
                     "INSERT OR REPLACE INTO images(dataset_id, name, size, sha256, width, "
                     "height, content_type) VALUES(?,?,?,?,?,?,?)");
    upsert.Bind(1, dataset_id).Bind(2, image.name).Bind(3, image.size).Bind(4, image.sha256);
    upsert.Bind(5, image.width).Bind(6, image.height).Bind(7, image.content_type).Run();
  }
  transaction.Commit();
}

bool SqliteJobStore::DeleteImage(const std::string& dataset_id, const std::string& name) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement remove(*writer_, "DELETE FROM images WHERE dataset_id = ? AND name = ?");
  remove.Bind(1, dataset_id).Bind(2, name).Run();
  return writer_->changes() > 0;
}

std::vector<ImageRecord> SqliteJobStore::ListImages(const std::string& dataset_id) {
  ReaderLease db = Reader();
  Statement select(*db,
                   "SELECT name, size, sha256, width, height, content_type FROM images "
                   "WHERE dataset_id = ? ORDER BY name");
  select.Bind(1, dataset_id);
  std::vector<ImageRecord> images;
  while (select.Step()) {
    images.push_back(ImageRecord{select.Text(0), select.Int(1), select.Text(2),
                                 static_cast<int>(select.Int(3)), static_cast<int>(select.Int(4)),
                                 select.Text(5)});
  }
  return images;
}

std::optional<ImageRecord> SqliteJobStore::GetImage(const std::string& dataset_id,
                                                    const std::string& name) {
  ReaderLease db = Reader();
  Statement select(*db,
                   "SELECT name, size, sha256, width, height, content_type FROM images "
                   "WHERE dataset_id = ? AND name = ?");
  select.Bind(1, dataset_id).Bind(2, name);
  if (!select.Step()) return std::nullopt;
  return ImageRecord{select.Text(0),
                     select.Int(1),
                     select.Text(2),
                     static_cast<int>(select.Int(3)),
                     static_cast<int>(select.Int(4)),
                     select.Text(5)};
}

JobRecord SqliteJobStore::CreateJob(const std::string& type, const std::string& dataset_id,
                                    const std::string& params) {
  JobRecord job;
  job.id = NewId();
  job.type = type;
  job.dataset_id = dataset_id;
  job.params = params;
  job.created_at = NowSeconds();
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement insert(*writer_,
                   "INSERT INTO jobs(id, type, dataset_id, params, state, created_at, queued_at) "
                   "VALUES(?,?,?,?,'queued',?,?)");
  insert.Bind(1, job.id).Bind(2, type).Bind(3, dataset_id).Bind(4, params);
  insert.Bind(5, job.created_at).Bind(6, job.created_at).Run();
  return job;
}

std::optional<JobRecord> SqliteJobStore::GetJob(const std::string& id) {
  ReaderLease db = Reader();
  return SelectJob(*db, id);
}

std::vector<JobRecord> SqliteJobStore::ListJobs(const JobFilter& filter) {
  ReaderLease db = Reader();
  Statement select(*db,
                   std::string("SELECT ") + kJobColumns +
                       " FROM jobs WHERE (?1 IS NULL OR state = ?1) AND (?2 IS NULL OR type = ?2)"
                       " AND (?3 IS NULL OR dataset_id = ?3) ORDER BY created_at DESC LIMIT ?4");
  if (filter.state) select.Bind(1, std::string(JobStateName(*filter.state)));
  select.Bind(2, filter.type).Bind(3, filter.dataset_id).Bind(4, filter.limit);
  std::vector<JobRecord> jobs;
  while (select.Step()) jobs.push_back(ReadJob(select));
  return jobs;
}

std::optional<JobRecord> SqliteJobStore::ClaimNextJob(const ClaimRequest& request) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Transaction transaction(*writer_);
  Statement next(*writer_,
                 "SELECT id FROM jobs WHERE state = 'queued' ORDER BY queued_at, rowid LIMIT 1");
  if (!next.Step()) return std::nullopt;
  const std::string id = next.Text(0);
  Statement claim(*writer_,
                  "UPDATE jobs SET state = 'running', started_at = ?, finished_at = NULL, "
                  "attempts = attempts + 1, progress_fraction = 0, progress_stage = 'starting', "
                  "progress_message = '', eta_s = NULL, worker_id = ?, lease_token = ?, "
                  "lease_expires_at = ? WHERE id = ?");
  const double now = NowSeconds();
  claim.Bind(1, now).Bind(2, request.worker_id).Bind(3, NewId()).Bind(4, now + request.lease_s);
  claim.Bind(5, id).Run();
  std::optional<JobRecord> job = SelectJob(*writer_, id);
  transaction.Commit();
  return job;
}

bool SqliteJobStore::RenewLease(const std::string& id, const std::string& lease_token,
                                double lease_s) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement renew(*writer_,
                  "UPDATE jobs SET lease_expires_at = ? WHERE id = ? AND state = 'running' AND "
                  "lease_token = ?");
  renew.Bind(1, NowSeconds() + lease_s).Bind(2, id).Bind(3, lease_token).Run();
  return writer_->changes() > 0;
}

void SqliteJobStore::UpdateProgress(const std::string& id, const JobProgress& progress) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement update(*writer_,
                   "UPDATE jobs SET progress_fraction = ?, progress_stage = ?, "
                   "progress_message = ?, eta_s = ? WHERE id = ? AND state = 'running'");
  update.Bind(1, progress.fraction).Bind(2, progress.stage).Bind(3, progress.message);
  update.Bind(4, progress.eta_s).Bind(5, id).Run();
}

std::optional<JobState> SqliteJobStore::RequestCancel(const std::string& id) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Transaction transaction(*writer_);
  std::optional<JobRecord> job = SelectJob(*writer_, id);
  if (!job) return std::nullopt;
  if (job->state == JobState::kQueued) {
    Statement cancel(*writer_,
                     "UPDATE jobs SET state = 'canceled', finished_at = ?, cancel_requested = 1 "
                     "WHERE id = ?");
    cancel.Bind(1, NowSeconds()).Bind(2, id).Run();
    job->state = JobState::kCanceled;
  } else if (job->state == JobState::kRunning) {
    Statement flag(*writer_, "UPDATE jobs SET cancel_requested = 1 WHERE id = ?");
    flag.Bind(1, id).Run();
  }
  transaction.Commit();
  return job->state;
}

bool SqliteJobStore::FinishJob(const std::string& id, const std::string& lease_token,
                               const JobOutcome& outcome) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Transaction transaction(*writer_);
  Statement finish(
      *writer_,
      "UPDATE jobs SET state = ?, finished_at = ?, error_code = ?, error_message = ?, "
      "result = ?, eta_s = NULL, progress_fraction = CASE WHEN ? THEN 1 ELSE "
      "progress_fraction END, lease_expires_at = NULL WHERE id = ? AND state = 'running' AND "
      "lease_token = ?");
  finish.Bind(1, std::string(JobStateName(outcome.state))).Bind(2, NowSeconds());
  if (outcome.error) {
    finish.Bind(3, outcome.error->code).Bind(4, outcome.error->message);
  } else {
    finish.BindNull(3).BindNull(4);
  }
  finish.Bind(5, outcome.result).Bind(6, outcome.state == JobState::kSucceeded ? 1 : 0);
  finish.Bind(7, id).Bind(8, lease_token).Run();
  if (writer_->changes() == 0) return false;
  Statement clear(*writer_, "DELETE FROM artifacts WHERE job_id = ?");
  clear.Bind(1, id).Run();
  for (const ArtifactRecord& artifact : outcome.artifacts) {
    Statement insert(*writer_,
                     "INSERT INTO artifacts(job_id, name, path, size, sha256, content_type) "
                     "VALUES(?,?,?,?,?,?)");
    insert.Bind(1, id).Bind(2, artifact.name).Bind(3, artifact.path).Bind(4, artifact.size);
    insert.Bind(5, artifact.sha256).Bind(6, artifact.content_type).Run();
  }
  transaction.Commit();
  return true;
}

bool SqliteJobStore::RequeueJob(const std::string& id, const std::string& lease_token) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement requeue(*writer_,
                    "UPDATE jobs SET state = 'queued', attempts = MAX(attempts - 1, 0), "
                    "started_at = NULL, progress_stage = 'requeued', eta_s = NULL, "
                    "lease_expires_at = NULL WHERE id = ? AND state = 'running' AND "
                    "lease_token = ?");
  requeue.Bind(1, id).Bind(2, lease_token).Run();
  return writer_->changes() > 0;
}

bool SqliteJobStore::RetryJob(const std::string& id) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Transaction transaction(*writer_);
  Statement retry(*writer_,
                  "UPDATE jobs SET state = 'queued', queued_at = ?, attempts = 0, started_at = "
                  "NULL, finished_at = NULL, error_code = NULL, error_message = NULL, result = "
                  "NULL, cancel_requested = 0, progress_fraction = 0, progress_stage = '', "
                  "progress_message = '', eta_s = NULL "
                  "WHERE id = ? AND state IN ('failed', 'canceled')");
  retry.Bind(1, NowSeconds()).Bind(2, id).Run();
  if (writer_->changes() == 0) return false;
  Statement clear(*writer_, "DELETE FROM artifacts WHERE job_id = ?");
  clear.Bind(1, id).Run();
  transaction.Commit();
  return true;
}

bool SqliteJobStore::DeleteJob(const std::string& id) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement remove(*writer_, "DELETE FROM jobs WHERE id = ? AND state != 'running'");
  remove.Bind(1, id).Run();
  return writer_->changes() > 0;
}

std::optional<std::string> SqliteJobStore::GetResult(const std::string& id) {
  ReaderLease db = Reader();
  Statement select(*db, "SELECT result FROM jobs WHERE id = ? AND state = 'succeeded'");
  select.Bind(1, id);
  if (!select.Step()) return std::nullopt;
  return select.OptionalText(0);
}

std::vector<ArtifactRecord> SqliteJobStore::ListArtifacts(const std::string& job_id) {
  ReaderLease db = Reader();
  Statement select(*db,
                   "SELECT name, path, size, sha256, content_type FROM artifacts "
                   "WHERE job_id = ? ORDER BY name");
  select.Bind(1, job_id);
  std::vector<ArtifactRecord> artifacts;
  while (select.Step()) {
    artifacts.push_back(ArtifactRecord{select.Text(0), select.Text(1), select.Int(2),
                                       select.Text(3), select.Text(4)});
  }
  return artifacts;
}

RecoveryReport SqliteJobStore::RecoverInterruptedJobs(int max_attempts) {
  return RecoverRunning(max_attempts, std::nullopt);
}

RecoveryReport SqliteJobStore::RecoverExpiredLeases(int max_attempts) {
  return RecoverRunning(max_attempts, NowSeconds());
}

RecoveryReport SqliteJobStore::RecoverRunning(int max_attempts,
                                              std::optional<double> expired_before) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Transaction transaction(*writer_);
  RecoveryReport report;
  // A job claimed before leases existed (no expiry) counts as expired.
  Statement running(*writer_,
                    "SELECT id, attempts, cancel_requested FROM jobs WHERE state = 'running' "
                    "AND (?1 IS NULL OR lease_expires_at IS NULL OR lease_expires_at <= ?1)");
  running.Bind(1, expired_before);
  const double now = NowSeconds();
  while (running.Step()) {
    const std::string id = running.Text(0);
    const int64_t attempts = running.Int(1);
    switch (DecideRecovery(running.Int(2) != 0, attempts, max_attempts)) {
      case RecoveryAction::kCancel: {
        Statement cancel(*writer_,
                         "UPDATE jobs SET state = 'canceled', finished_at = ?, lease_expires_at "
                         "= NULL WHERE id = ?");
        cancel.Bind(1, now).Bind(2, id).Run();
        report.canceled.push_back(id);
        break;
      }
      case RecoveryAction::kFail: {
        Statement fail(*writer_,
                       "UPDATE jobs SET state = 'failed', finished_at = ?, error_code = "
                       "'interrupted', error_message = ?, lease_expires_at = NULL WHERE id = ?");
        fail.Bind(1, now).Bind(2, InterruptedMessage(attempts, max_attempts)).Bind(3, id).Run();
        report.failed.push_back(id);
        break;
      }
      case RecoveryAction::kRequeue: {
        Statement requeue(*writer_,
                          "UPDATE jobs SET state = 'queued', started_at = NULL, progress_stage = "
                          "'requeued', eta_s = NULL, lease_expires_at = NULL WHERE id = ?");
        requeue.Bind(1, id).Run();
        report.requeued.push_back(id);
        break;
      }
    }
  }
  transaction.Commit();
  return report;
}

bool SqliteJobStore::ImportDataset(const DatasetRecord& dataset) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement insert(*writer_, "INSERT OR IGNORE INTO datasets(id, name, created_at) VALUES(?,?,?)");
  insert.Bind(1, dataset.id).Bind(2, dataset.name).Bind(3, dataset.created_at).Run();
  return writer_->changes() > 0;
}

bool SqliteJobStore::ImportJob(const JobRecord& job, const std::optional<std::string>& result,
                               const std::vector<ArtifactRecord>& artifacts) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Transaction transaction(*writer_);
  Statement insert(*writer_,
                   "INSERT OR IGNORE INTO jobs(id, type, dataset_id, params, state, "
                   "progress_fraction, progress_stage, progress_message, eta_s, created_at, "
                   "queued_at, started_at, finished_at, attempts, error_code, error_message, "
                   "result, cancel_requested, worker_id, lease_token, lease_expires_at) "
                   "VALUES(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
  insert.Bind(1, job.id).Bind(2, job.type).Bind(3, job.dataset_id).Bind(4, job.params);
  insert.Bind(5, std::string(JobStateName(job.state))).Bind(6, job.progress.fraction);
  insert.Bind(7, job.progress.stage).Bind(8, job.progress.message).Bind(9, job.progress.eta_s);
  insert.Bind(10, job.created_at).Bind(11, job.created_at).Bind(12, job.started_at);
  insert.Bind(13, job.finished_at).Bind(14, job.attempts);
  if (job.error) {
    insert.Bind(15, job.error->code).Bind(16, job.error->message);
  } else {
    insert.BindNull(15).BindNull(16);
  }
  insert.Bind(17, result).Bind(18, job.cancel_requested ? 1 : 0).Bind(19, job.worker_id);
  insert.Bind(20, job.lease_token).Bind(21, job.lease_expires_at).Run();
  if (writer_->changes() == 0) return false;
  for (const ArtifactRecord& artifact : artifacts) {
    Statement add(*writer_,
                  "INSERT INTO artifacts(job_id, name, path, size, sha256, content_type) "
                  "VALUES(?,?,?,?,?,?)");
    add.Bind(1, job.id).Bind(2, artifact.name).Bind(3, artifact.path).Bind(4, artifact.size);
    add.Bind(5, artifact.sha256).Bind(6, artifact.content_type).Run();
  }
  transaction.Commit();
  return true;
}

void SqliteJobStore::RecordHeartbeat(const WorkerRecord& worker) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Statement upsert(*writer_,
                   "INSERT INTO workers(id, started_at, last_seen_at, running_jobs) "
                   "VALUES(?1, ?2, ?3, ?4) ON CONFLICT(id) DO UPDATE SET last_seen_at = ?3, "
                   "running_jobs = ?4");
  upsert.Bind(1, worker.id).Bind(2, worker.started_at).Bind(3, NowSeconds());
  upsert.Bind(4, JoinIds(worker.running_jobs)).Run();
}

std::vector<WorkerRecord> SqliteJobStore::ListWorkers(double seen_within_s) {
  ReaderLease db = Reader();
  Statement select(*db,
                   "SELECT id, started_at, last_seen_at, running_jobs FROM workers "
                   "WHERE last_seen_at >= ? ORDER BY id");
  select.Bind(1, NowSeconds() - seen_within_s);
  std::vector<WorkerRecord> workers;
  while (select.Step()) {
    workers.push_back(
        WorkerRecord{select.Text(0), select.Double(1), select.Double(2), SplitIds(select.Text(3))});
  }
  return workers;
}

std::map<JobState, int64_t> SqliteJobStore::CountJobsByState() {
  ReaderLease db = Reader();
  std::map<JobState, int64_t> counts;
  for (JobState state : AllJobStates()) counts[state] = 0;
  Statement select(*db, "SELECT state, COUNT(*) FROM jobs GROUP BY state");
  while (select.Step()) {
    if (auto state = ParseJobState(select.Text(0))) counts[*state] = select.Int(1);
  }
  return counts;
}

int64_t SqliteJobStore::CountActiveJobs(const std::string& dataset_id) {
  ReaderLease db = Reader();
  Statement select(*db,
                   "SELECT COUNT(*) FROM jobs WHERE dataset_id = ? AND state IN "
                   "('queued', 'running')");
  select.Bind(1, dataset_id);
  select.Step();
  return select.Int(0);
}

std::string SqliteJobStore::IntegrityCheck() {
  ReaderLease db = Reader();
  Statement check(*db, "PRAGMA integrity_check");
  std::string problems;
  while (check.Step()) {
    if (!problems.empty()) problems += "; ";
    problems += check.Text(0);
  }
  return problems;
}

}  // namespace omnirig::storage
