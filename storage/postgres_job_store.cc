#include "storage/postgres_job_store.h"

#include <libpq-fe.h>
#include <poll.h>

#include <cstdio>
#include <cstdlib>

namespace omnirig::storage {
namespace {

// Schema migrations, the same versions as SqliteJobStore's (kMigrations there), in PostgreSQL's
// dialect. Never edit a shipped entry: append a new one. `seq` orders jobs queued in the same
// instant (SQLite's rowid).
const char* const kMigrations[] = {
    R"sql(
CREATE TABLE datasets(
  id TEXT PRIMARY KEY,
  name TEXT NOT NULL,
  created_at DOUBLE PRECISION NOT NULL);
CREATE TABLE images(
  dataset_id TEXT NOT NULL REFERENCES datasets(id) ON DELETE CASCADE,
  name TEXT NOT NULL,
  size BIGINT NOT NULL,
  sha256 TEXT NOT NULL,
  width INTEGER NOT NULL,
  height INTEGER NOT NULL,
  content_type TEXT NOT NULL,
  PRIMARY KEY(dataset_id, name));
CREATE TABLE jobs(
  seq BIGSERIAL UNIQUE,
  id TEXT PRIMARY KEY,
  type TEXT NOT NULL,
  dataset_id TEXT NOT NULL,
  params TEXT NOT NULL,
  state TEXT NOT NULL CHECK(state IN ('queued','running','succeeded','failed','canceled')),
  progress_fraction DOUBLE PRECISION NOT NULL DEFAULT 0,
  progress_stage TEXT NOT NULL DEFAULT '',
  progress_message TEXT NOT NULL DEFAULT '',
  eta_s DOUBLE PRECISION,
  created_at DOUBLE PRECISION NOT NULL,
  queued_at DOUBLE PRECISION NOT NULL,
  started_at DOUBLE PRECISION,
  finished_at DOUBLE PRECISION,
  attempts INTEGER NOT NULL DEFAULT 0,
  error_code TEXT,
  error_message TEXT,
  result TEXT,
  cancel_requested INTEGER NOT NULL DEFAULT 0);
CREATE INDEX jobs_by_state ON jobs(state, queued_at, seq);
CREATE INDEX jobs_by_dataset ON jobs(dataset_id);
CREATE TABLE artifacts(
  job_id TEXT NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
  name TEXT NOT NULL,
  path TEXT NOT NULL,
  size BIGINT NOT NULL,
  sha256 TEXT NOT NULL,
  content_type TEXT NOT NULL,
  PRIMARY KEY(job_id, name));
)sql",
    // 2: leases (who runs a job, until when) and worker heartbeats.
    R"sql(
ALTER TABLE jobs ADD COLUMN worker_id TEXT NOT NULL DEFAULT '';
ALTER TABLE jobs ADD COLUMN lease_token TEXT NOT NULL DEFAULT '';
ALTER TABLE jobs ADD COLUMN lease_expires_at DOUBLE PRECISION;
CREATE TABLE workers(
  id TEXT PRIMARY KEY,
  started_at DOUBLE PRECISION NOT NULL,
  last_seen_at DOUBLE PRECISION NOT NULL,
  running_jobs TEXT NOT NULL DEFAULT '');
)sql",
};

constexpr char kChannel[] = "omnirig_jobs";
// The database server's clock, in epoch seconds: lease expiry is compared on one clock.
constexpr char kDbNow[] = "EXTRACT(EPOCH FROM clock_timestamp())::DOUBLE PRECISION";
// Serialises migrations of processes starting together (an arbitrary constant).
constexpr char kMigrationLock[] = "SELECT pg_advisory_xact_lock(7210418309)";

constexpr char kJobColumns[] =
    "id, type, dataset_id, params, state, progress_fraction, progress_stage, progress_message, "
    "eta_s, created_at, started_at, finished_at, attempts, error_code, error_message, "
    "cancel_requested, worker_id, lease_token, lease_expires_at";

using Param = std::optional<std::string>;

Param P(const std::string& value) { return value; }
Param P(int64_t value) { return std::to_string(value); }
Param P(double value) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.17g", value);
  return std::string(text);
}
Param P(const std::optional<double>& value) { return value ? P(*value) : std::nullopt; }
Param P(const std::optional<std::string>& value) { return value; }

// One query's result; rows and columns are 0-based.
class Result {
 public:
  explicit Result(PGresult* result) : result_(result) {}
  ~Result() { PQclear(result_); }
  Result(Result&& other) noexcept : result_(other.result_) { other.result_ = nullptr; }
  Result(const Result&) = delete;
  Result& operator=(const Result&) = delete;

  int rows() const { return PQntuples(result_); }
  int64_t affected() const {
    const char* count = PQcmdTuples(result_);
    return count[0] ? std::strtoll(count, nullptr, 10) : 0;
  }
  bool IsNull(int row, int column) const { return PQgetisnull(result_, row, column) != 0; }
  std::string Text(int row, int column) const { return PQgetvalue(result_, row, column); }
  int64_t Int(int row, int column) const {
    return std::strtoll(PQgetvalue(result_, row, column), nullptr, 10);
  }
  double Double(int row, int column) const {
    return std::strtod(PQgetvalue(result_, row, column), nullptr);
  }
  std::optional<double> OptionalDouble(int row, int column) const {
    if (IsNull(row, column)) return std::nullopt;
    return Double(row, column);
  }
  std::optional<std::string> OptionalText(int row, int column) const {
    if (IsNull(row, column)) return std::nullopt;
    return Text(row, column);
  }

 private:
  PGresult* result_;
};

void Check(PGconn* db, PGresult* result) {
  const ExecStatusType status = PQresultStatus(result);
  if (status == PGRES_COMMAND_OK || status == PGRES_TUPLES_OK) return;
  throw PostgresError(std::string("PostgreSQL: ") +
                      (result ? PQresultErrorMessage(result) : PQerrorMessage(db)));
}

// Runs `sql` with text parameters $1..$n; throws PostgresError unless it succeeded.
Result Run(PGconn* db, const std::string& sql, const std::vector<Param>& params = {}) {
  std::vector<const char*> values;
  values.reserve(params.size());
  for (const Param& param : params) values.push_back(param ? param->c_str() : nullptr);
  PGresult* raw = PQexecParams(db, sql.c_str(), static_cast<int>(values.size()), nullptr,
                               values.data(), nullptr, nullptr, 0);
  Result result(raw);
  Check(db, raw);
  return result;
}

// BEGIN on construction; ROLLBACK unless Commit() was called.
class Transaction {
 public:
  explicit Transaction(PGconn* db) : db_(db) { Run(db_, "BEGIN"); }
  ~Transaction() {
    if (!done_) PQclear(PQexec(db_, "ROLLBACK"));
  }
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;
  void Commit() {
    Run(db_, "COMMIT");
    done_ = true;
  }

 private:
  PGconn* db_;
  bool done_ = false;
};

JobRecord ReadJob(const Result& rows, int row) {
  JobRecord job;
  job.id = rows.Text(row, 0);
  job.type = rows.Text(row, 1);
  job.dataset_id = rows.Text(row, 2);
  job.params = rows.Text(row, 3);
  job.state = ParseJobState(rows.Text(row, 4)).value_or(JobState::kFailed);
  job.progress = JobProgress{rows.Double(row, 5), rows.Text(row, 6), rows.Text(row, 7),
                             rows.OptionalDouble(row, 8)};
  job.created_at = rows.Double(row, 9);
  job.started_at = rows.OptionalDouble(row, 10);
  job.finished_at = rows.OptionalDouble(row, 11);
  job.attempts = static_cast<int>(rows.Int(row, 12));
  if (!rows.IsNull(row, 13)) job.error = JobError{rows.Text(row, 13), rows.Text(row, 14)};
  job.cancel_requested = rows.Int(row, 15) != 0;
  job.worker_id = rows.Text(row, 16);
  job.lease_token = rows.Text(row, 17);
  job.lease_expires_at = rows.OptionalDouble(row, 18);
  return job;
}

std::optional<JobRecord> SelectJob(PGconn* db, const std::string& id, bool for_update = false) {
  const Result rows = Run(db,
                          std::string("SELECT ") + kJobColumns + " FROM jobs WHERE id = $1" +
                              (for_update ? " FOR UPDATE" : ""),
                          {P(id)});
  if (rows.rows() == 0) return std::nullopt;
  return ReadJob(rows, 0);
}

constexpr char kDatasetSelect[] =
    "SELECT d.id, d.name, d.created_at, "
    "COUNT(i.name) - COUNT(CASE WHEN i.content_type LIKE 'video/%' THEN 1 END), "
    "COALESCE(SUM(i.size), 0), COUNT(CASE WHEN i.content_type LIKE 'video/%' THEN 1 END) "
    "FROM datasets d LEFT JOIN images i ON i.dataset_id = d.id ";

DatasetRecord ReadDataset(const Result& rows, int row) {
  return DatasetRecord{rows.Text(row, 0), rows.Text(row, 1), rows.Double(row, 2),
                       rows.Int(row, 3),  rows.Int(row, 4),  rows.Int(row, 5)};
}

ImageRecord ReadImage(const Result& rows, int row) {
  return ImageRecord{rows.Text(row, 0),
                     rows.Int(row, 1),
                     rows.Text(row, 2),
                     static_cast<int>(rows.Int(row, 3)),
                     static_cast<int>(rows.Int(row, 4)),
                     rows.Text(row, 5)};
}

PGconn* Connect(const std::string& url) {
  PGconn* db = PQconnectdb(url.c_str());
  if (PQstatus(db) != CONNECTION_OK) {
    const std::string message = PQerrorMessage(db);
    PQfinish(db);
    throw PostgresError("cannot connect to PostgreSQL: " + message);
  }
  // Notices (e.g. "relation already exists, skipping") are not errors; keep stderr quiet.
  PQsetNoticeProcessor(
      db, [](void*, const char*) {}, nullptr);
  return db;
}

}  // namespace

bool IsPostgresUrl(const std::string& url) {
  return url.rfind("postgresql://", 0) == 0 || url.rfind("postgres://", 0) == 0;
}

// A connection borrowed from the pool for one call; one broken by a network error is closed
// rather than returned, and the next borrow opens a fresh one.
class PostgresJobStore::Lease {
 public:
  Lease(PostgresJobStore& store, PGconn* db) : store_(&store), db_(db) {}
  Lease(Lease&& other) noexcept : store_(other.store_), db_(other.db_) { other.db_ = nullptr; }
  Lease(const Lease&) = delete;
  Lease& operator=(const Lease&) = delete;
  ~Lease() {
    if (!db_) return;
    std::lock_guard<std::mutex> lock(store_->pool_mutex_);
    if (PQstatus(db_) == CONNECTION_OK && PQtransactionStatus(db_) == PQTRANS_IDLE) {
      store_->idle_.push_back(db_);
    } else {
      PQfinish(db_);
      --store_->open_;
    }
    store_->pool_available_.notify_one();
  }
  PGconn* get() const { return db_; }

 private:
  PostgresJobStore* store_;
  PGconn* db_;
};

PostgresJobStore::PostgresJobStore(const std::string& url, int max_connections)
    : url_(url), max_connections_(std::max(1, max_connections)) {
  try {
    Migrate();
  } catch (...) {
    // No destructor runs for a constructor that throws: the migration's connection, back in the
    // pool by now, is closed here.
    CloseConnections();
    throw;
  }
}

PostgresJobStore::~PostgresJobStore() { CloseConnections(); }

void PostgresJobStore::CloseConnections() {
  for (PGconn* db : idle_) PQfinish(db);
  idle_.clear();
  if (listener_) PQfinish(listener_);
  listener_ = nullptr;
}

int PostgresJobStore::SchemaVersion() {
  return static_cast<int>(sizeof(kMigrations) / sizeof(kMigrations[0]));
}

PostgresJobStore::Lease PostgresJobStore::Borrow() {
  std::unique_lock<std::mutex> lock(pool_mutex_);
  pool_available_.wait(lock, [this] { return !idle_.empty() || open_ < max_connections_; });
  if (!idle_.empty()) {
    PGconn* db = idle_.back();
    idle_.pop_back();
    return Lease(*this, db);
  }
  ++open_;
  lock.unlock();
  try {
    return Lease(*this, Connect(url_));
  } catch (...) {
    lock.lock();
    --open_;
    pool_available_.notify_one();
    throw;
  }
}

void PostgresJobStore::Migrate() {
  Lease db = Borrow();
  Transaction transaction(db.get());
  Run(db.get(), kMigrationLock);
  Run(db.get(), "CREATE TABLE IF NOT EXISTS omnirig_schema(version INTEGER NOT NULL)");
  const Result current = Run(db.get(), "SELECT version FROM omnirig_schema");
  int version = 0;
  if (current.rows() == 0) {
    Run(db.get(), "INSERT INTO omnirig_schema(version) VALUES(0)");
  } else {
    version = static_cast<int>(current.Int(0, 0));
  }
  if (version > SchemaVersion()) {
    throw PostgresError("database " + url_ + " has schema version " + std::to_string(version) +
                        ", newer than this build's " + std::to_string(SchemaVersion()));
  }
  for (int next = version; next < SchemaVersion(); ++next) {
    PGresult* raw = PQexec(db.get(), kMigrations[next]);  // several statements: no parameters
    Result result(raw);
    Check(db.get(), raw);
    Run(db.get(), "UPDATE omnirig_schema SET version = $1", {P(int64_t{next + 1})});
  }
  transaction.Commit();
}

int PostgresJobStore::StoredSchemaVersion() {
  Lease db = Borrow();
  const Result rows = Run(db.get(), "SELECT version FROM omnirig_schema");
  return rows.rows() == 0 ? 0 : static_cast<int>(rows.Int(0, 0));
}

DatasetRecord PostgresJobStore::CreateDataset(const std::string& name) {
  DatasetRecord dataset{NewId(), name, NowSeconds(), 0, 0};
  Lease db = Borrow();
  Run(db.get(), "INSERT INTO datasets(id, name, created_at) VALUES($1, $2, $3)",
      {P(dataset.id), P(dataset.name), P(dataset.created_at)});
  return dataset;
}

std::vector<DatasetRecord> PostgresJobStore::ListDatasets() {
  Lease db = Borrow();
  const Result rows =
      Run(db.get(), std::string(kDatasetSelect) + "GROUP BY d.id ORDER BY d.created_at DESC");
  std::vector<DatasetRecord> datasets;
  for (int row = 0; row < rows.rows(); ++row) datasets.push_back(ReadDataset(rows, row));
  return datasets;
}

std::optional<DatasetRecord> PostgresJobStore::GetDataset(const std::string& id) {
  Lease db = Borrow();
  const Result rows =
      Run(db.get(), std::string(kDatasetSelect) + "WHERE d.id = $1 GROUP BY d.id", {P(id)});
  if (rows.rows() == 0) return std::nullopt;
  return ReadDataset(rows, 0);
}

bool PostgresJobStore::DeleteDataset(const std::string& id) {
  Lease db = Borrow();
  return Run(db.get(), "DELETE FROM datasets WHERE id = $1", {P(id)}).affected() > 0;
}

void PostgresJobStore::PutImage(const std::string& dataset_id, const ImageRecord& image) {
  PutImages(dataset_id, {image});
}

void PostgresJobStore::PutImages(const std::string& dataset_id,
                                 const std::vector<ImageRecord>& images) {
  Lease db = Borrow();
  Transaction transaction(db.get());
  for (const ImageRecord& image : images) {
    Run(db.get(),
        "INSERT INTO images(dataset_id, name, size, sha256, width, height, content_type) "
        "VALUES($1, $2, $3, $4, $5, $6, $7) ON CONFLICT(dataset_id, name) DO UPDATE SET "
        "size = EXCLUDED.size, sha256 = EXCLUDED.sha256, width = EXCLUDED.width, "
        "height = EXCLUDED.height, content_type = EXCLUDED.content_type",
        {P(dataset_id), P(image.name), P(image.size), P(image.sha256), P(int64_t{image.width}),
         P(int64_t{image.height}), P(image.content_type)});
  }
  transaction.Commit();
}

bool PostgresJobStore::DeleteImage(const std::string& dataset_id, const std::string& name) {
  Lease db = Borrow();
  return Run(db.get(), "DELETE FROM images WHERE dataset_id = $1 AND name = $2",
             {P(dataset_id), P(name)})
             .affected() > 0;
}

std::vector<ImageRecord> PostgresJobStore::ListImages(const std::string& dataset_id) {
  Lease db = Borrow();
  const Result rows = Run(db.get(),
                          "SELECT name, size, sha256, width, height, content_type FROM images "
                          "WHERE dataset_id = $1 ORDER BY name COLLATE \"C\"",
                          {P(dataset_id)});
  std::vector<ImageRecord> images;
  for (int row = 0; row < rows.rows(); ++row) images.push_back(ReadImage(rows, row));
  return images;
}

std::optional<ImageRecord> PostgresJobStore::GetImage(const std::string& dataset_id,
                                                      const std::string& name) {
  Lease db = Borrow();
  const Result rows = Run(db.get(),
                          "SELECT name, size, sha256, width, height, content_type FROM images "
                          "WHERE dataset_id = $1 AND name = $2",
                          {P(dataset_id), P(name)});
  if (rows.rows() == 0) return std::nullopt;
  return ReadImage(rows, 0);
}

JobRecord PostgresJobStore::CreateJob(const std::string& type, const std::string& dataset_id,
                                      const std::string& params) {
  JobRecord job;
  job.id = NewId();
  job.type = type;
  job.dataset_id = dataset_id;
  job.params = params;
  job.created_at = NowSeconds();
  Lease db = Borrow();
  // One statement, one implicit transaction: the notification goes out when the row commits.
  Run(db.get(),
      "WITH queued AS (INSERT INTO jobs(id, type, dataset_id, params, state, created_at, "
      "queued_at) VALUES($1, $2, $3, $4, 'queued', $5, $5) RETURNING id) "
      "SELECT pg_notify('omnirig_jobs', id) FROM queued",
      {P(job.id), P(type), P(dataset_id), P(params), P(job.created_at)});
  return job;
}

std::optional<JobRecord> PostgresJobStore::GetJob(const std::string& id) {
  Lease db = Borrow();
  return SelectJob(db.get(), id);
}

std::vector<JobRecord> PostgresJobStore::ListJobs(const JobFilter& filter) {
  Lease db = Borrow();
  const Result rows =
      Run(db.get(),
          std::string("SELECT ") + kJobColumns +
              " FROM jobs WHERE ($1::TEXT IS NULL OR state = $1) AND ($2::TEXT IS NULL OR "
              "type = $2) AND ($3::TEXT IS NULL OR dataset_id = $3) "
              "ORDER BY created_at DESC, seq DESC "
              "LIMIT CASE WHEN $4::BIGINT < 0 THEN NULL ELSE $4::BIGINT END",
          {filter.state ? P(std::string(JobStateName(*filter.state))) : std::nullopt,
           P(filter.type), P(filter.dataset_id), P(int64_t{filter.limit})});
  std::vector<JobRecord> jobs;
  for (int row = 0; row < rows.rows(); ++row) jobs.push_back(ReadJob(rows, row));
  return jobs;
}

std::optional<JobRecord> PostgresJobStore::ClaimNextJob(const ClaimRequest& request) {
  Lease db = Borrow();
  // SKIP LOCKED: a row another worker is claiming right now is passed over, not waited for.
  const Result rows =
      Run(db.get(),
          std::string("UPDATE jobs SET state = 'running', started_at = $1, finished_at = NULL, "
                      "attempts = attempts + 1, progress_fraction = 0, progress_stage = "
                      "'starting', progress_message = '', eta_s = NULL, worker_id = $2, "
                      "lease_token = $3, lease_expires_at = ") +
              kDbNow +
              " + $4 WHERE id = (SELECT id FROM jobs WHERE state = 'queued' "
              "ORDER BY queued_at, seq LIMIT 1 FOR UPDATE SKIP LOCKED) RETURNING " +
              kJobColumns,
          {P(NowSeconds()), P(request.worker_id), P(NewId()), P(request.lease_s)});
  if (rows.rows() == 0) return std::nullopt;
  return ReadJob(rows, 0);
}

bool PostgresJobStore::RenewLease(const std::string& id, const std::string& lease_token,
                                  double lease_s) {
  Lease db = Borrow();
  return Run(db.get(),
             std::string("UPDATE jobs SET lease_expires_at = ") + kDbNow +
                 " + $1 WHERE id = $2 AND state = 'running' AND lease_token = $3",
             {P(lease_s), P(id), P(lease_token)})
             .affected() > 0;
}

void PostgresJobStore::UpdateProgress(const std::string& id, const JobProgress& progress) {
  Lease db = Borrow();
  Run(db.get(),
      "UPDATE jobs SET progress_fraction = $1, progress_stage = $2, progress_message = $3, "
      "eta_s = $4 WHERE id = $5 AND state = 'running'",
      {P(progress.fraction), P(progress.stage), P(progress.message), P(progress.eta_s), P(id)});
}

std::optional<JobState> PostgresJobStore::RequestCancel(const std::string& id) {
  Lease db = Borrow();
  Transaction transaction(db.get());
  std::optional<JobRecord> job = SelectJob(db.get(), id, /*for_update=*/true);
  if (!job) return std::nullopt;
  if (job->state == JobState::kQueued) {
    Run(db.get(),
        "UPDATE jobs SET state = 'canceled', finished_at = $1, cancel_requested = 1 "
        "WHERE id = $2",
        {P(NowSeconds()), P(id)});
    job->state = JobState::kCanceled;
  } else if (job->state == JobState::kRunning) {
    Run(db.get(), "UPDATE jobs SET cancel_requested = 1 WHERE id = $1", {P(id)});
  }
  transaction.Commit();
  return job->state;
}

bool PostgresJobStore::FinishJob(const std::string& id, const std::string& lease_token,
                                 const JobOutcome& outcome) {
  Lease db = Borrow();
  Transaction transaction(db.get());
  const Result finished =
      Run(db.get(),
          "UPDATE jobs SET state = $1, finished_at = $2, error_code = $3, error_message = $4, "
          "result = $5, eta_s = NULL, progress_fraction = CASE WHEN $6 THEN 1 ELSE "
          "progress_fraction END, lease_expires_at = NULL WHERE id = $7 AND state = 'running' "
          "AND lease_token = $8",
          {P(std::string(JobStateName(outcome.state))), P(NowSeconds()),
           outcome.error ? P(outcome.error->code) : std::nullopt,
           outcome.error ? P(outcome.error->message) : std::nullopt, P(outcome.result),
           P(std::string(outcome.state == JobState::kSucceeded ? "true" : "false")), P(id),
           P(lease_token)});
  if (finished.affected() == 0) return false;
  Run(db.get(), "DELETE FROM artifacts WHERE job_id = $1", {P(id)});
  for (const ArtifactRecord& artifact : outcome.artifacts) {
    Run(db.get(),
        "INSERT INTO artifacts(job_id, name, path, size, sha256, content_type) "
        "VALUES($1, $2, $3, $4, $5, $6)",
        {P(id), P(artifact.name), P(artifact.path), P(artifact.size), P(artifact.sha256),
         P(artifact.content_type)});
  }
  transaction.Commit();
  return true;
}

bool PostgresJobStore::RequeueJob(const std::string& id, const std::string& lease_token) {
  Lease db = Borrow();
  Transaction transaction(db.get());
  const Result requeued =
      Run(db.get(),
          "UPDATE jobs SET state = 'queued', attempts = GREATEST(attempts - 1, 0), "
          "started_at = NULL, progress_stage = 'requeued', eta_s = NULL, lease_expires_at = "
          "NULL WHERE id = $1 AND state = 'running' AND lease_token = $2",
          {P(id), P(lease_token)});
  if (requeued.affected() == 0) return false;
  Run(db.get(), std::string("NOTIFY ") + kChannel);
  transaction.Commit();
  return true;
}

bool PostgresJobStore::RetryJob(const std::string& id) {
  Lease db = Borrow();
  Transaction transaction(db.get());
  const Result retried =
      Run(db.get(),
          "UPDATE jobs SET state = 'queued', queued_at = $1, attempts = 0, started_at = NULL, "
          "finished_at = NULL, error_code = NULL, error_message = NULL, result = NULL, "
          "cancel_requested = 0, progress_fraction = 0, progress_stage = '', "
          "progress_message = '', eta_s = NULL "
          "WHERE id = $2 AND state IN ('failed', 'canceled')",
          {P(NowSeconds()), P(id)});
  if (retried.affected() == 0) return false;
  Run(db.get(), "DELETE FROM artifacts WHERE job_id = $1", {P(id)});
  Run(db.get(), std::string("NOTIFY ") + kChannel);
  transaction.Commit();
  return true;
}

bool PostgresJobStore::DeleteJob(const std::string& id) {
  Lease db = Borrow();
  return Run(db.get(), "DELETE FROM jobs WHERE id = $1 AND state != 'running'", {P(id)})
             .affected() > 0;
}

std::optional<std::string> PostgresJobStore::GetResult(const std::string& id) {
  Lease db = Borrow();
  const Result rows =
      Run(db.get(), "SELECT result FROM jobs WHERE id = $1 AND state = 'succeeded'", {P(id)});
  if (rows.rows() == 0) return std::nullopt;
  return rows.OptionalText(0, 0);
}

std::vector<ArtifactRecord> PostgresJobStore::ListArtifacts(const std::string& job_id) {
  Lease db = Borrow();
  const Result rows = Run(db.get(),
                          "SELECT name, path, size, sha256, content_type FROM artifacts "
                          "WHERE job_id = $1 ORDER BY name COLLATE \"C\"",
                          {P(job_id)});
  std::vector<ArtifactRecord> artifacts;
  for (int row = 0; row < rows.rows(); ++row) {
    artifacts.push_back(ArtifactRecord{rows.Text(row, 0), rows.Text(row, 1), rows.Int(row, 2),
                                       rows.Text(row, 3), rows.Text(row, 4)});
  }
  return artifacts;
}

RecoveryReport PostgresJobStore::RecoverInterruptedJobs(int max_attempts) {
  return RecoverRunning(max_attempts, /*only_expired=*/false);
}

RecoveryReport PostgresJobStore::RecoverExpiredLeases(int max_attempts) {
  return RecoverRunning(max_attempts, /*only_expired=*/true);
}

RecoveryReport PostgresJobStore::RecoverRunning(int max_attempts, bool only_expired) {
  Lease db = Borrow();
  Transaction transaction(db.get());
  // SKIP LOCKED: a job being finished or renewed right now is not expired; leave it.
  const Result running =
      Run(db.get(),
          std::string("SELECT id, attempts, cancel_requested FROM jobs WHERE state = 'running' ") +
              (only_expired ? std::string("AND (lease_expires_at IS NULL OR lease_expires_at <= ") +
                                  kDbNow + ") "
                            : std::string()) +
              "ORDER BY seq FOR UPDATE SKIP LOCKED");
  RecoveryReport report;
  const double now = NowSeconds();
  for (int row = 0; row < running.rows(); ++row) {
    const std::string id = running.Text(row, 0);
    const int64_t attempts = running.Int(row, 1);
    switch (DecideRecovery(running.Int(row, 2) != 0, attempts, max_attempts)) {
      case RecoveryAction::kCancel:
        Run(db.get(),
            "UPDATE jobs SET state = 'canceled', finished_at = $1, lease_expires_at = NULL "
            "WHERE id = $2",
            {P(now), P(id)});
        report.canceled.push_back(id);
        break;
      case RecoveryAction::kFail:
        Run(db.get(),
            "UPDATE jobs SET state = 'failed', finished_at = $1, error_code = 'interrupted', "
            "error_message = $2, lease_expires_at = NULL WHERE id = $3",
            {P(now), P(InterruptedMessage(attempts, max_attempts)), P(id)});
        report.failed.push_back(id);
        break;
      case RecoveryAction::kRequeue:
        Run(db.get(),
            "UPDATE jobs SET state = 'queued', started_at = NULL, progress_stage = 'requeued', "
            "eta_s = NULL, lease_expires_at = NULL WHERE id = $1",
            {P(id)});
        report.requeued.push_back(id);
        break;
    }
  }
  if (!report.requeued.empty()) Run(db.get(), std::string("NOTIFY ") + kChannel);
  transaction.Commit();
  return report;
}

std::map<JobState, int64_t> PostgresJobStore::CountJobsByState() {
  Lease db = Borrow();
  std::map<JobState, int64_t> counts;
  for (JobState state : AllJobStates()) counts[state] = 0;
  const Result rows = Run(db.get(), "SELECT state, COUNT(*) FROM jobs GROUP BY state");
  for (int row = 0; row < rows.rows(); ++row) {
    if (auto state = ParseJobState(rows.Text(row, 0))) counts[*state] = rows.Int(row, 1);
  }
  return counts;
}

int64_t PostgresJobStore::CountActiveJobs(const std::string& dataset_id) {
  Lease db = Borrow();
  return Run(db.get(),
             "SELECT COUNT(*) FROM jobs WHERE dataset_id = $1 AND state IN ('queued', "
             "'running')",
             {P(dataset_id)})
      .Int(0, 0);
}

bool PostgresJobStore::ImportDataset(const DatasetRecord& dataset) {
  Lease db = Borrow();
  return Run(db.get(),
             "INSERT INTO datasets(id, name, created_at) VALUES($1, $2, $3) "
             "ON CONFLICT(id) DO NOTHING",
             {P(dataset.id), P(dataset.name), P(dataset.created_at)})
             .affected() > 0;
}

bool PostgresJobStore::ImportJob(const JobRecord& job, const std::optional<std::string>& result,
                                 const std::vector<ArtifactRecord>& artifacts) {
  Lease db = Borrow();
  Transaction transaction(db.get());
  const Result inserted =
      Run(db.get(),
          "INSERT INTO jobs(id, type, dataset_id, params, state, progress_fraction, "
          "progress_stage, progress_message, eta_s, created_at, queued_at, started_at, "
          "finished_at, attempts, error_code, error_message, result, cancel_requested, "
          "worker_id, lease_token, lease_expires_at) VALUES($1, $2, $3, $4, $5, $6, $7, $8, $9, "
          "$10, $10, $11, $12, $13, $14, $15, $16, $17, $18, $19, $20) "
          "ON CONFLICT(id) DO NOTHING",
          {P(job.id),
           P(job.type),
           P(job.dataset_id),
           P(job.params),
           P(std::string(JobStateName(job.state))),
           P(job.progress.fraction),
           P(job.progress.stage),
           P(job.progress.message),
           P(job.progress.eta_s),
           P(job.created_at),
           P(job.started_at),
           P(job.finished_at),
           P(int64_t{job.attempts}),
           job.error ? P(job.error->code) : std::nullopt,
           job.error ? P(job.error->message) : std::nullopt,
           P(result),
           P(int64_t{job.cancel_requested ? 1 : 0}),
           P(job.worker_id),
           P(job.lease_token),
           P(job.lease_expires_at)});
  if (inserted.affected() == 0) return false;
  for (const ArtifactRecord& artifact : artifacts) {
    Run(db.get(),
        "INSERT INTO artifacts(job_id, name, path, size, sha256, content_type) "
        "VALUES($1, $2, $3, $4, $5, $6)",
        {P(job.id), P(artifact.name), P(artifact.path), P(artifact.size), P(artifact.sha256),
         P(artifact.content_type)});
  }
  // A queued job copied in is work for the workers.
  if (job.state == JobState::kQueued) Run(db.get(), std::string("NOTIFY ") + kChannel);
  transaction.Commit();
  return true;
}

void PostgresJobStore::RecordHeartbeat(const WorkerRecord& worker) {
  Lease db = Borrow();
  Run(db.get(),
      "INSERT INTO workers(id, started_at, last_seen_at, running_jobs) VALUES($1, $2, $3, $4) "
      "ON CONFLICT(id) DO UPDATE SET last_seen_at = EXCLUDED.last_seen_at, "
      "running_jobs = EXCLUDED.running_jobs",
      {P(worker.id), P(worker.started_at), P(NowSeconds()), P(JoinIds(worker.running_jobs))});
}

std::vector<WorkerRecord> PostgresJobStore::ListWorkers(double seen_within_s) {
  Lease db = Borrow();
  const Result rows = Run(db.get(),
                          "SELECT id, started_at, last_seen_at, running_jobs FROM workers "
                          "WHERE last_seen_at >= $1 ORDER BY id COLLATE \"C\"",
                          {P(NowSeconds() - seen_within_s)});
  std::vector<WorkerRecord> workers;
  for (int row = 0; row < rows.rows(); ++row) {
    workers.push_back(WorkerRecord{rows.Text(row, 0), rows.Double(row, 1), rows.Double(row, 2),
                                   SplitIds(rows.Text(row, 3))});
  }
  return workers;
}

bool PostgresJobStore::WaitForQueueChange(double timeout_s) {
  std::lock_guard<std::mutex> lock(listener_mutex_);
  if (listener_ && PQstatus(listener_) != CONNECTION_OK) {
    PQfinish(listener_);
    listener_ = nullptr;
  }
  if (!listener_) {
    listener_ = Connect(url_);
    Run(listener_, std::string("LISTEN ") + kChannel);
    return true;  // a job queued while no one listened: look at the queue now
  }
  auto drain = [this] {
    bool notified = false;
    PQconsumeInput(listener_);
    while (PGnotify* notify = PQnotifies(listener_)) {
      notified = true;
      PQfreemem(notify);
    }
    return notified;
  };
  if (drain()) return true;
  pollfd ready{PQsocket(listener_), POLLIN, 0};
  if (ready.fd < 0) return true;
  if (::poll(&ready, 1, static_cast<int>(timeout_s * 1000)) <= 0) return false;
  return drain() || PQstatus(listener_) != CONNECTION_OK;
}

std::string PostgresJobStore::IntegrityCheck() {
  Lease db = Borrow();
  const Result rows = Run(db.get(),
                          "SELECT COUNT(*) FROM artifacts a LEFT JOIN jobs j ON j.id = a.job_id "
                          "WHERE j.id IS NULL");
  if (rows.Int(0, 0) != 0) return std::to_string(rows.Int(0, 0)) + " artifact(s) without a job";
  return "ok";
}

}  // namespace omnirig::storage
