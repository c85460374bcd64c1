#include "storage/sql_job_store.h"

#include <algorithm>

namespace omnirig::storage {
namespace {

constexpr char kDatasetSelect[] =
    "SELECT d.id, d.name, d.created_at, "
    "COUNT(i.name) - COUNT(CASE WHEN i.content_type LIKE 'video/%' OR i.content_type LIKE "
    "'application/%' THEN 1 END), "
    "COALESCE(SUM(i.size), 0), COUNT(CASE WHEN i.content_type LIKE 'video/%' THEN 1 END) "
    "FROM datasets d LEFT JOIN images i ON i.dataset_id = d.id ";
constexpr char kImageSelect[] =
    "SELECT name, size, sha256, width, height, content_type FROM images ";
constexpr char kInsertArtifact[] =
    "INSERT INTO artifacts(job_id, name, path, size, sha256, content_type) "
    "VALUES(?1, ?2, ?3, ?4, ?5, ?6)";

DatasetRecord ReadDataset(const SqlRow& row) {
  return DatasetRecord{row.Text(0), row.Text(1), row.Double(2), row.Int(3), row.Int(4), row.Int(5)};
}

ImageRecord ReadImage(const SqlRow& row) {
  return ImageRecord{row.Text(0),
                     row.Int(1),
                     row.Text(2),
                     static_cast<int>(row.Int(3)),
                     static_cast<int>(row.Int(4)),
                     row.Text(5)};
}

ArtifactRecord ReadArtifact(const SqlRow& row) {
  return ArtifactRecord{row.Text(0), row.Text(1), row.Int(2), row.Text(3), row.Text(4)};
}

// A list of job ids as stored in one text column ("a,b,c") and back.
std::string JoinIds(const std::vector<std::string>& ids) {
  std::string joined;
  for (const std::string& id : ids) joined += (joined.empty() ? "" : ",") + id;
  return joined;
}

std::vector<std::string> SplitIds(const std::string& joined) {
  std::vector<std::string> ids;
  size_t start = 0;
  while (start < joined.size()) {
    const size_t comma = std::min(joined.find(',', start), joined.size());
    if (comma > start) ids.push_back(joined.substr(start, comma - start));
    start = comma + 1;
  }
  return ids;
}

WorkerRecord ReadWorker(const SqlRow& row) {
  return WorkerRecord{row.Text(0), row.Double(1), row.Double(2), SplitIds(row.Text(3))};
}

void InsertArtifacts(SqlSession& db, const std::string& job_id,
                     const std::vector<ArtifactRecord>& artifacts) {
  for (const ArtifactRecord& artifact : artifacts) {
    db.Execute(kInsertArtifact, {job_id, artifact.name, artifact.path, artifact.size,
                                 artifact.sha256, artifact.content_type});
  }
}

// The columns ReadJob reads, in its order.
constexpr char kJobColumns[] =
    "id, type, dataset_id, params, state, progress_fraction, progress_stage, progress_message, "
    "eta_s, created_at, started_at, finished_at, attempts, error_code, error_message, "
    "cancel_requested, worker_id, lease_token, lease_expires_at";

JobRecord ReadJob(const SqlRow& row) {
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

// The job `id` read on `db`, with `suffix` appended to its SELECT (a row lock).
std::optional<JobRecord> SelectJob(SqlSession& db, const std::string& id,
                                   const std::string& suffix = "") {
  // Built once: a status poll is one lookup.
  static const std::string kSelect =
      std::string("SELECT ") + kJobColumns + " FROM jobs WHERE id = ?1";
  return db.First(suffix.empty() ? kSelect : kSelect + suffix, {id}, &ReadJob);
}

// The error's code and message, NULL and NULL without one.
SqlValue ErrorCode(const std::optional<JobError>& error) {
  return error ? SqlValue(error->code) : SqlValue();
}
SqlValue ErrorMessage(const std::optional<JobError>& error) {
  return error ? SqlValue(error->message) : SqlValue();
}

// A running job found interrupted, as recovery decides its fate.
struct RunningJob {
  std::string id;
  int64_t attempts = 0;
  bool cancel_requested = false;
};

// Cancels, fails or requeues each of `running` on `db`: a requested cancel wins, then a job that
// used up `max_attempts` runs fails ("interrupted"), else it runs again.
RecoveryReport Recover(SqlSession& db, const std::vector<RunningJob>& running, int max_attempts) {
  RecoveryReport report;
  const double now = NowSeconds();
  for (const RunningJob& job : running) {
    if (job.cancel_requested) {
      db.Execute(
          "UPDATE jobs SET state = 'canceled', finished_at = ?1, lease_expires_at = NULL "
          "WHERE id = ?2",
          {now, job.id});
      report.canceled.push_back(job.id);
    } else if (job.attempts >= max_attempts) {
      db.Execute(
          "UPDATE jobs SET state = 'failed', finished_at = ?1, error_code = 'interrupted', "
          "error_message = ?2, lease_expires_at = NULL WHERE id = ?3",
          {now,
           "the job's worker stopped during each of its " + std::to_string(job.attempts) +
               " attempts (maximum " + std::to_string(max_attempts) + ")",
           job.id});
      report.failed.push_back(job.id);
    } else {
      db.Execute(
          "UPDATE jobs SET state = 'queued', started_at = NULL, progress_stage = 'requeued', "
          "eta_s = NULL, lease_expires_at = NULL WHERE id = ?1",
          {job.id});
      report.requeued.push_back(job.id);
    }
  }
  return report;
}

}  // namespace

namespace {

// Version 1: datasets, images, jobs and artifacts.
std::string SchemaVersion1(const SqlDialect& dialect) {
  const std::string& real = dialect.real_type;
  const std::string& int64 = dialect.int64_type;
  const std::string insertion_column =
      dialect.insertion_order_column.empty() ? "" : "\n  " + dialect.insertion_order_column + ",";
  const std::string insertion_key =
      dialect.insertion_order_column.empty() ? "" : ", " + dialect.insertion_order;
  return R"sql(
CREATE TABLE datasets(
  id TEXT PRIMARY KEY,
  name TEXT NOT NULL,
  created_at )sql" + real + R"sql( NOT NULL);
CREATE TABLE images(
  dataset_id TEXT NOT NULL REFERENCES datasets(id) ON DELETE CASCADE,
  name TEXT NOT NULL,
  size )sql" + int64 + R"sql( NOT NULL,
  sha256 TEXT NOT NULL,
  width INTEGER NOT NULL,
  height INTEGER NOT NULL,
  content_type TEXT NOT NULL,
  PRIMARY KEY(dataset_id, name));
CREATE TABLE jobs()sql" + insertion_column + R"sql(
  id TEXT PRIMARY KEY,
  type TEXT NOT NULL,
  dataset_id TEXT NOT NULL,
  params TEXT NOT NULL,
  state TEXT NOT NULL CHECK(state IN ('queued','running','succeeded','failed','canceled')),
  progress_fraction )sql" + real + R"sql( NOT NULL DEFAULT 0,
  progress_stage TEXT NOT NULL DEFAULT '',
  progress_message TEXT NOT NULL DEFAULT '',
  eta_s )sql" + real + R"sql(,
  created_at )sql" + real + R"sql( NOT NULL,
  queued_at )sql" + real + R"sql( NOT NULL,
  started_at )sql" + real + R"sql(,
  finished_at )sql" + real + R"sql(,
  attempts INTEGER NOT NULL DEFAULT 0,
  error_code TEXT,
  error_message TEXT,
  result TEXT,
  cancel_requested INTEGER NOT NULL DEFAULT 0);
CREATE INDEX jobs_by_state ON jobs(state, queued_at)sql" + insertion_key + R"sql();
CREATE INDEX jobs_by_dataset ON jobs(dataset_id);
CREATE TABLE artifacts(
  job_id TEXT NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
  name TEXT NOT NULL,
  path TEXT NOT NULL,
  size )sql" + int64 + R"sql( NOT NULL,
  sha256 TEXT NOT NULL,
  content_type TEXT NOT NULL,
  PRIMARY KEY(job_id, name));
)sql";
}

// Version 2: leases (who runs a job, until when) and worker heartbeats.
std::string SchemaVersion2(const SqlDialect& dialect) {
  const std::string& real = dialect.real_type;
  return R"sql(
ALTER TABLE jobs ADD COLUMN worker_id TEXT NOT NULL DEFAULT '';
ALTER TABLE jobs ADD COLUMN lease_token TEXT NOT NULL DEFAULT '';
ALTER TABLE jobs ADD COLUMN lease_expires_at )sql" + real + R"sql(;
CREATE TABLE workers(
  id TEXT PRIMARY KEY,
  started_at )sql" + real + R"sql( NOT NULL,
  last_seen_at )sql" + real + R"sql( NOT NULL,
  running_jobs TEXT NOT NULL DEFAULT '');
)sql";
}

}  // namespace

std::vector<std::string> SchemaMigrations(const SqlDialect& dialect) {
  return {SchemaVersion1(dialect), SchemaVersion2(dialect)};
}

const char SqlJobStore::kInsertJob[] =
    "INSERT INTO jobs(id, type, dataset_id, params, state, created_at, queued_at) "
    "VALUES(?1, ?2, ?3, ?4, 'queued', ?5, ?5)";

JobRecord SqlJobStore::NewJob(const std::string& type, const std::string& dataset_id,
                              const std::string& params) {
  JobRecord job;
  job.id = NewId();
  job.type = type;
  job.dataset_id = dataset_id;
  job.params = params;
  job.created_at = NowSeconds();
  return job;
}

DatasetRecord SqlJobStore::CreateDataset(const std::string& name) {
  DatasetRecord dataset{NewId(), name, NowSeconds(), 0, 0};
  WithWriter([&](SqlSession& db) {
    db.Execute("INSERT INTO datasets(id, name, created_at) VALUES(?1, ?2, ?3)",
               {dataset.id, dataset.name, dataset.created_at});
  });
  return dataset;
}

std::vector<DatasetRecord> SqlJobStore::ListDatasets() {
  return Read([&](SqlSession& db) {
    return db.All(std::string(kDatasetSelect) + "GROUP BY d.id ORDER BY d.created_at DESC", {},
                  &ReadDataset);
  });
}

std::optional<DatasetRecord> SqlJobStore::GetDataset(const std::string& id) {
  return Read([&](SqlSession& db) {
    return db.First(std::string(kDatasetSelect) + "WHERE d.id = ?1 GROUP BY d.id", {id},
                    &ReadDataset);
  });
}

bool SqlJobStore::DeleteDataset(const std::string& id) {
  return Write(
      [&](SqlSession& db) { return db.Execute("DELETE FROM datasets WHERE id = ?1", {id}) > 0; });
}

void SqlJobStore::PutImage(const std::string& dataset_id, const ImageRecord& image) {
  PutImages(dataset_id, {image});
}

// One commit (one WAL fsync on SQLite) for the whole batch instead of one per record.
void SqlJobStore::PutImages(const std::string& dataset_id, const std::vector<ImageRecord>& images) {
  InTransaction([&](SqlSession& db) {
    for (const ImageRecord& image : images) {
      db.Execute(
          "INSERT INTO images(dataset_id, name, size, sha256, width, height, content_type) "
          "VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7) ON CONFLICT(dataset_id, name) DO UPDATE SET "
          "size = excluded.size, sha256 = excluded.sha256, width = excluded.width, "
          "height = excluded.height, content_type = excluded.content_type",
          {dataset_id, image.name, image.size, image.sha256, image.width, image.height,
           image.content_type});
    }
    return true;
  });
}

bool SqlJobStore::DeleteImage(const std::string& dataset_id, const std::string& name) {
  return Write([&](SqlSession& db) {
    return db.Execute("DELETE FROM images WHERE dataset_id = ?1 AND name = ?2",
                      {dataset_id, name}) > 0;
  });
}

std::vector<ImageRecord> SqlJobStore::ListImages(const std::string& dataset_id) {
  return Read([&](SqlSession& db) {
    return db.All(
        std::string(kImageSelect) + "WHERE dataset_id = ?1 ORDER BY name" + dialect_.byte_order,
        {dataset_id}, &ReadImage);
  });
}

std::optional<ImageRecord> SqlJobStore::GetImage(const std::string& dataset_id,
                                                 const std::string& name) {
  return Read([&](SqlSession& db) {
    return db.First(std::string(kImageSelect) + "WHERE dataset_id = ?1 AND name = ?2",
                    {dataset_id, name}, &ReadImage);
  });
}

std::optional<JobRecord> SqlJobStore::GetJob(const std::string& id) {
  return Read([&](SqlSession& db) { return SelectJob(db, id); });
}

std::vector<JobRecord> SqlJobStore::ListJobs(const JobFilter& filter) {
  const int64_t limit = filter.limit < 0 ? INT64_MAX : filter.limit;
  return Read([&](SqlSession& db) {
    return db.All(std::string("SELECT ") + kJobColumns +
                      " FROM jobs WHERE (CAST(?1 AS TEXT) IS NULL OR state = ?1) AND (CAST(?2 AS "
                      "TEXT) IS NULL OR type = ?2) AND (CAST(?3 AS TEXT) IS NULL OR dataset_id = "
                      "?3) ORDER BY created_at DESC, " +
                      dialect_.insertion_order + " DESC LIMIT ?4",
                  {filter.state ? SqlValue(JobStateName(*filter.state)) : SqlValue(), filter.type,
                   filter.dataset_id, limit},
                  &ReadJob);
  });
}

// One statement: the oldest queued job is taken and returned as it is now running.
std::optional<JobRecord> SqlJobStore::ClaimNextJob(const ClaimRequest& request) {
  return Write([&](SqlSession& db) {
    return db.First(
        "UPDATE jobs SET state = 'running', started_at = ?1, finished_at = NULL, attempts = "
        "attempts + 1, progress_fraction = 0, progress_stage = 'starting', progress_message = '', "
        "eta_s = NULL, worker_id = ?2, lease_token = ?3, lease_expires_at = " +
            dialect_.now +
            " + ?4 WHERE id = (SELECT id FROM jobs WHERE state = 'queued' ORDER BY "
            "queued_at, " +
            dialect_.insertion_order + " LIMIT 1" + dialect_.skip_locked + ") RETURNING " +
            kJobColumns,
        {NowSeconds(), request.worker_id, NewId(), request.lease_s}, &ReadJob);
  });
}

JobRecord SqlJobStore::CreateClaimedJob(const std::string& type, const std::string& dataset_id,
                                        const std::string& params, const ClaimRequest& request) {
  const JobRecord job = NewJob(type, dataset_id, params);
  return Write([&](SqlSession& db) {
    db.Execute(
        "INSERT INTO jobs(id, type, dataset_id, params, state, created_at, queued_at, started_at, "
        "attempts, progress_fraction, progress_stage, progress_message, worker_id, lease_token, "
        "lease_expires_at) VALUES(?1, ?2, ?3, ?4, 'running', ?5, ?5, ?5, 1, 0, 'starting', '', "
        "?6, ?7, " +
            dialect_.now + " + ?8)",
        {job.id, type, dataset_id, params, job.created_at, request.worker_id, NewId(),
         request.lease_s});
    return *SelectJob(db, job.id);
  });
}

bool SqlJobStore::RenewLease(const std::string& id, const std::string& lease_token,
                             double lease_s) {
  return Write([&](SqlSession& db) {
    return db.Execute("UPDATE jobs SET lease_expires_at = " + dialect_.now +
                          " + ?1 WHERE id = ?2 AND state = 'running' AND lease_token = ?3",
                      {lease_s, id, lease_token}) > 0;
  });
}

void SqlJobStore::UpdateProgress(const std::string& id, const JobProgress& progress) {
  WithWriter([&](SqlSession& db) {
    db.Execute(
        "UPDATE jobs SET progress_fraction = ?1, progress_stage = ?2, progress_message = ?3, "
        "eta_s = ?4 WHERE id = ?5 AND state = 'running'",
        {progress.fraction, progress.stage, progress.message, progress.eta_s, id});
  });
}

std::optional<JobState> SqlJobStore::RequestCancel(const std::string& id) {
  std::optional<JobState> state;
  InTransaction([&](SqlSession& db) {
    const std::optional<JobRecord> job = SelectJob(db, id, dialect_.lock_row);
    if (!job) return false;
    state = job->state;
    if (job->state == JobState::kQueued) {
      db.Execute(
          "UPDATE jobs SET state = 'canceled', finished_at = ?1, cancel_requested = 1 "
          "WHERE id = ?2",
          {NowSeconds(), id});
      state = JobState::kCanceled;
    } else if (job->state == JobState::kRunning) {
      db.Execute("UPDATE jobs SET cancel_requested = 1 WHERE id = ?1", {id});
    }
    return true;
  });
  return state;
}

bool SqlJobStore::FinishJob(const std::string& id, const std::string& lease_token,
                            const JobOutcome& outcome) {
  return InTransaction([&](SqlSession& db) {
    const int64_t finished = db.Execute(
        "UPDATE jobs SET state = ?1, finished_at = ?2, error_code = ?3, error_message = ?4, "
        "result = ?5, eta_s = NULL, progress_fraction = CASE WHEN ?1 = 'succeeded' THEN 1 "
        "ELSE progress_fraction END, lease_expires_at = NULL WHERE id = ?6 AND "
        "state = 'running' AND lease_token = ?7",
        {JobStateName(outcome.state), NowSeconds(), ErrorCode(outcome.error),
         ErrorMessage(outcome.error), outcome.result, id, lease_token});
    if (finished == 0) return false;
    db.Execute("DELETE FROM artifacts WHERE job_id = ?1", {id});
    InsertArtifacts(db, id, outcome.artifacts);
    return true;
  });
}

bool SqlJobStore::RequeueJob(const std::string& id, const std::string& lease_token) {
  return InTransaction([&](SqlSession& db) {
    const int64_t requeued = db.Execute(
        "UPDATE jobs SET state = 'queued', attempts = CASE WHEN attempts >= 1 THEN attempts - 1 "
        "ELSE 0 END, started_at = NULL, progress_stage = 'requeued', eta_s = NULL, "
        "lease_expires_at = NULL WHERE id = ?1 AND state = 'running' AND lease_token = ?2",
        {id, lease_token});
    if (requeued == 0) return false;
    OnJobsQueued(db);
    return true;
  });
}

bool SqlJobStore::RetryJob(const std::string& id) {
  return InTransaction([&](SqlSession& db) {
    const int64_t retried = db.Execute(
        "UPDATE jobs SET state = 'queued', queued_at = ?1, attempts = 0, started_at = NULL, "
        "finished_at = NULL, error_code = NULL, error_message = NULL, result = NULL, "
        "cancel_requested = 0, progress_fraction = 0, progress_stage = '', "
        "progress_message = '', eta_s = NULL WHERE id = ?2 AND state IN ('failed', 'canceled')",
        {NowSeconds(), id});
    if (retried == 0) return false;
    db.Execute("DELETE FROM artifacts WHERE job_id = ?1", {id});
    OnJobsQueued(db);
    return true;
  });
}

bool SqlJobStore::DeleteJob(const std::string& id) {
  return Write([&](SqlSession& db) {
    return db.Execute("DELETE FROM jobs WHERE id = ?1 AND state != 'running'", {id}) > 0;
  });
}

std::optional<std::string> SqlJobStore::GetResult(const std::string& id) {
  return Read([&](SqlSession& db) {
    std::optional<std::string> result;
    db.Query("SELECT result FROM jobs WHERE id = ?1 AND state = 'succeeded'", {id},
             [&](const SqlRow& row) { result = row.OptionalText(0); });
    return result;
  });
}

std::vector<ArtifactRecord> SqlJobStore::ListArtifacts(const std::string& job_id) {
  return Read([&](SqlSession& db) {
    return db.All(
        "SELECT name, path, size, sha256, content_type FROM artifacts "
        "WHERE job_id = ?1 ORDER BY name" +
            dialect_.byte_order,
        {job_id}, &ReadArtifact);
  });
}

std::map<JobState, int64_t> SqlJobStore::CountJobsByState() {
  std::map<JobState, int64_t> counts;
  for (JobState state : AllJobStates()) counts[state] = 0;
  WithReader([&](SqlSession& db) {
    db.Query("SELECT state, COUNT(*) FROM jobs GROUP BY state", {}, [&](const SqlRow& row) {
      if (auto state = ParseJobState(row.Text(0))) counts[*state] = row.Int(1);
    });
  });
  return counts;
}

int64_t SqlJobStore::CountActiveJobs(const std::string& dataset_id) {
  return Read([&](SqlSession& db) {
    int64_t count = 0;
    db.Query("SELECT COUNT(*) FROM jobs WHERE dataset_id = ?1 AND state IN ('queued', 'running')",
             {dataset_id}, [&](const SqlRow& row) { count = row.Int(0); });
    return count;
  });
}

bool SqlJobStore::ImportDataset(const DatasetRecord& dataset) {
  return Write([&](SqlSession& db) {
    return db.Execute(
               "INSERT INTO datasets(id, name, created_at) VALUES(?1, ?2, ?3) "
               "ON CONFLICT(id) DO NOTHING",
               {dataset.id, dataset.name, dataset.created_at}) > 0;
  });
}

bool SqlJobStore::ImportJob(const JobRecord& job, const std::optional<std::string>& result,
                            const std::vector<ArtifactRecord>& artifacts) {
  return InTransaction([&](SqlSession& db) {
    const int64_t inserted = db.Execute(
        "INSERT INTO jobs(id, type, dataset_id, params, state, progress_fraction, "
        "progress_stage, progress_message, eta_s, created_at, queued_at, started_at, "
        "finished_at, attempts, error_code, error_message, result, cancel_requested, "
        "worker_id, lease_token, lease_expires_at) VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, "
        "?10, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, ?18, ?19, ?20) ON CONFLICT(id) DO NOTHING",
        {job.id,
         job.type,
         job.dataset_id,
         job.params,
         JobStateName(job.state),
         job.progress.fraction,
         job.progress.stage,
         job.progress.message,
         job.progress.eta_s,
         job.created_at,
         job.started_at,
         job.finished_at,
         job.attempts,
         ErrorCode(job.error),
         ErrorMessage(job.error),
         result,
         job.cancel_requested ? 1 : 0,
         job.worker_id,
         job.lease_token,
         job.lease_expires_at});
    if (inserted == 0) return false;
    InsertArtifacts(db, job.id, artifacts);
    // A queued job copied in is work for the workers.
    if (job.state == JobState::kQueued) OnJobsQueued(db);
    return true;
  });
}

void SqlJobStore::RecordHeartbeat(const WorkerRecord& worker) {
  WithWriter([&](SqlSession& db) {
    db.Execute(
        "INSERT INTO workers(id, started_at, last_seen_at, running_jobs) VALUES(?1, ?2, ?3, ?4) "
        "ON CONFLICT(id) DO UPDATE SET last_seen_at = excluded.last_seen_at, "
        "running_jobs = excluded.running_jobs",
        {worker.id, worker.started_at, NowSeconds(), JoinIds(worker.running_jobs)});
  });
}

std::vector<WorkerRecord> SqlJobStore::ListWorkers(double seen_within_s) {
  return Read([&](SqlSession& db) {
    return db.All(
        "SELECT id, started_at, last_seen_at, running_jobs FROM workers "
        "WHERE last_seen_at >= ?1 ORDER BY id" +
            dialect_.byte_order,
        {NowSeconds() - seen_within_s}, &ReadWorker);
  });
}

RecoveryReport SqlJobStore::RecoverInterruptedJobs(int max_attempts) {
  return RecoverRunning(max_attempts, /*only_expired=*/false);
}

RecoveryReport SqlJobStore::RecoverExpiredLeases(int max_attempts) {
  return RecoverRunning(max_attempts, /*only_expired=*/true);
}

RecoveryReport SqlJobStore::RecoverRunning(int max_attempts, bool only_expired) {
  RecoveryReport report;
  // A job claimed before leases existed (no expiry) counts as expired.
  const std::string expired =
      only_expired ? " AND (lease_expires_at IS NULL OR lease_expires_at <= " + dialect_.now + ")"
                   : "";
  InTransaction([&](SqlSession& db) {
    std::vector<RunningJob> running;
    db.Query("SELECT id, attempts, cancel_requested FROM jobs WHERE state = 'running'" + expired +
                 " ORDER BY " + dialect_.insertion_order + dialect_.skip_locked,
             {}, [&](const SqlRow& row) {
               running.push_back(RunningJob{row.Text(0), row.Int(1), row.Int(2) != 0});
             });
    report = Recover(db, running, max_attempts);
    if (!report.requeued.empty()) OnJobsQueued(db);
    return true;
  });
  return report;
}

}  // namespace omnirig::storage
