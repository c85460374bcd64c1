#pragma once
// What the SQLite and PostgreSQL job stores share: the schema's columns, reading rows into
// records, and every method whose SQL both dialects run as written. A store supplies its
// connections (SqlSession) and how it takes them: SqliteJobStore reads through a pool of reader
// connections and writes through one writer; PostgresJobStore borrows a pooled connection and
// announces queued jobs with NOTIFY (OnJobsQueued). Where their SQL differs in a phrase (the
// clock leases are compared on, SKIP LOCKED, the insertion order, the schema's type names) the
// SqlDialect names it. The schema's migrations are written once (SchemaMigrations); where each
// store keeps its version, job creation (NOTIFY in the insert) and the integrity check stay in
// each store.

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "storage/job_store.h"

namespace omnirig::storage {

// A query parameter: NULL (std::monostate), an integer, a real or text (NULL for an empty
// optional).
class SqlValue {
 public:
  using Value = std::variant<std::monostate, int64_t, double, std::string>;
  SqlValue() = default;
  // Implicit, so that a parameter list reads {id, 1, 2.5}.
  // NOLINTBEGIN(google-explicit-constructor)
  SqlValue(int value) : value_(int64_t{value}) {}
  SqlValue(int64_t value) : value_(value) {}
  SqlValue(double value) : value_(value) {}
  SqlValue(std::string value) : value_(std::move(value)) {}
  SqlValue(const char* value) : value_(std::string(value)) {}
  template <typename T>
  SqlValue(const std::optional<T>& value) : SqlValue(value ? SqlValue(*value) : SqlValue()) {}
  // NOLINTEND(google-explicit-constructor)

  const Value& value() const { return value_; }

 private:
  Value value_;
};

// One row of a query's result; columns are 0-based.
class SqlRow {
 public:
  virtual ~SqlRow() = default;
  virtual bool IsNull(int column) const = 0;
  virtual std::string Text(int column) const = 0;
  virtual int64_t Int(int column) const = 0;
  virtual double Double(int column) const = 0;
  std::optional<double> OptionalDouble(int column) const {
    return IsNull(column) ? std::nullopt : std::optional<double>(Double(column));
  }
  std::optional<std::string> OptionalText(int column) const {
    return IsNull(column) ? std::nullopt : std::optional<std::string>(Text(column));
  }
};

// One connection's statements. SQL is written with SQLite's numbered parameters ?1..?n (the
// PostgreSQL session rewrites them as $1..$n); errors throw the database's error type.
class SqlSession {
 public:
  virtual ~SqlSession() = default;
  // Runs `sql` and calls `each_row` for every row of its result, in order.
  virtual void Query(const std::string& sql, const std::vector<SqlValue>& params,
                     const std::function<void(const SqlRow&)>& each_row) = 0;
  // Runs a statement without rows; returns how many rows it changed.
  virtual int64_t Execute(const std::string& sql, const std::vector<SqlValue>& params = {}) = 0;

  // The rows of `sql`, each read by `read`.
  template <typename T>
  std::vector<T> All(const std::string& sql, const std::vector<SqlValue>& params,
                     T (*read)(const SqlRow&)) {
    std::vector<T> rows;
    Query(sql, params, [&](const SqlRow& row) { rows.push_back(read(row)); });
    return rows;
  }
  // The first row of `sql` read by `read`, nullopt when there is none.
  template <typename T>
  std::optional<T> First(const std::string& sql, const std::vector<SqlValue>& params,
                         T (*read)(const SqlRow&)) {
    std::optional<T> first;
    Query(sql, params, [&](const SqlRow& row) {
      if (!first) first = read(row);
    });
    return first;
  }
};

// What differs in the SQL of the methods SqlJobStore implements.
struct SqlDialect {
  // Appended to ORDER BY on a text column so that names sort by their bytes in both databases
  // (SQLite's default; PostgreSQL's follows the locale).
  std::string byte_order;
  // Appended to the SELECT of a row the same transaction then updates (empty where the
  // transaction holds the database's write lock from its start).
  std::string lock_row;
  // The column that orders rows inserted in the same instant (SQLite's rowid, a sequence).
  std::string insertion_order;
  // Appended to the SELECT of the jobs a claim or recovery takes: a row another process is
  // claiming, finishing or renewing right now is passed over, not waited for (empty where one
  // process holds the database's write lock).
  std::string skip_locked;
  // The clock, in epoch seconds, that lease expiry is written and compared on: one clock for
  // every process sharing the store (PostgreSQL's server; SQLite's is this machine's).
  std::string now;
  // The schema's type names: a double (REAL, DOUBLE PRECISION) and a 64-bit integer (SQLite's
  // INTEGER is 64 bits; PostgreSQL's is 32).
  std::string real_type;
  std::string int64_type;
  // The jobs table's column that `insertion_order` names, declared (empty where the database
  // has one of its own, SQLite's rowid).
  std::string insertion_order_column;
};

// The schema's migrations in `dialect`, applied in order; a store records how many it applied.
// Never edit a shipped entry: append a new one.
std::vector<std::string> SchemaMigrations(const SqlDialect& dialect);

class SqlJobStore : public JobStore {
 public:
  explicit SqlJobStore(SqlDialect dialect) : dialect_(std::move(dialect)) {}

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

  std::optional<JobRecord> GetJob(const std::string& id) override;
  std::vector<JobRecord> ListJobs(const JobFilter& filter) override;
  std::optional<JobRecord> ClaimNextJob(const ClaimRequest& request) override;
  JobRecord CreateClaimedJob(const std::string& type, const std::string& dataset_id,
                             const std::string& params, const ClaimRequest& request) override;
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
  std::map<JobState, int64_t> CountJobsByState() override;
  int64_t CountActiveJobs(const std::string& dataset_id) override;
  bool ImportDataset(const DatasetRecord& dataset) override;
  bool ImportJob(const JobRecord& job, const std::optional<std::string>& result,
                 const std::vector<ArtifactRecord>& artifacts) override;
  void RecordHeartbeat(const WorkerRecord& worker) override;
  std::vector<WorkerRecord> ListWorkers(double seen_within_s) override;
  RecoveryReport RecoverInterruptedJobs(int max_attempts) override;
  RecoveryReport RecoverExpiredLeases(int max_attempts) override;

 protected:
  // INSERT of a new queued job: id, type, dataset_id, params, created_at (= queued_at).
  static const char kInsertJob[];
  // A new queued job's record (what kInsertJob stores).
  static JobRecord NewJob(const std::string& type, const std::string& dataset_id,
                          const std::string& params);

  // Runs `work` on a connection for reading.
  virtual void WithReader(const std::function<void(SqlSession&)>& work) = 0;
  // Runs `work` on a connection for writing, each statement committed on its own.
  virtual void WithWriter(const std::function<void(SqlSession&)>& work) = 0;
  // Runs `work` in one write transaction, committed when `work` returns true and rolled back
  // when it returns false or throws; returns what `work` returned.
  virtual bool InTransaction(const std::function<bool(SqlSession&)>& work) = 0;
  // Called inside the transaction of a change that queued jobs, before it commits.
  virtual void OnJobsQueued(SqlSession& /*db*/) {}

  // WithReader and WithWriter returning what `work` returns.
  template <typename Work>
  auto Read(Work work) {
    decltype(work(std::declval<SqlSession&>())) value{};
    WithReader([&](SqlSession& db) { value = work(db); });
    return value;
  }
  template <typename Work>
  auto Write(Work work) {
    decltype(work(std::declval<SqlSession&>())) value{};
    WithWriter([&](SqlSession& db) { value = work(db); });
    return value;
  }

 private:
  // Cancels, fails or requeues the running jobs (those whose lease expired when `only_expired`),
  // in one transaction.
  RecoveryReport RecoverRunning(int max_attempts, bool only_expired);

  SqlDialect dialect_;
};

}  // namespace omnirig::storage
