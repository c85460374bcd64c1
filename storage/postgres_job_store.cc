#include "storage/postgres_job_store.h"

#include <libpq-fe.h>
#include <poll.h>

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <type_traits>

namespace omnirig::storage {
namespace {

constexpr char kChannel[] = "omnirig_jobs";
// The database server's clock, in epoch seconds: lease expiry is compared on one clock.
constexpr char kDbNow[] = "EXTRACT(EPOCH FROM clock_timestamp())::DOUBLE PRECISION";

// PostgreSQL's dialect; `seq` orders jobs queued in the same instant (SQLite's rowid).
SqlDialect Dialect() {
  return SqlDialect{/*byte_order=*/" COLLATE \"C\"", /*lock_row=*/" FOR UPDATE",
                    /*insertion_order=*/"seq", /*skip_locked=*/" FOR UPDATE SKIP LOCKED",
                    /*now=*/kDbNow, /*real_type=*/"DOUBLE PRECISION", /*int64_type=*/"BIGINT",
                    /*insertion_order_column=*/"seq BIGSERIAL UNIQUE"};
}

// Serialises migrations of processes starting together (an arbitrary constant).
constexpr char kMigrationLock[] = "SELECT pg_advisory_xact_lock(7210418309)";

// A parameter as libpq's text format; NULL stays NULL.
std::optional<std::string> Text(const SqlValue& param) {
  return std::visit(
      [](const auto& value) -> std::optional<std::string> {
        using T = std::decay_t<decltype(value)>;
        if constexpr (std::is_same_v<T, std::monostate>) {
          return std::nullopt;
        } else if constexpr (std::is_same_v<T, std::string>) {
          return value;
        } else if constexpr (std::is_same_v<T, double>) {
          char text[32];
          std::snprintf(text, sizeof(text), "%.17g", value);
          return std::string(text);
        } else {
          return std::to_string(value);
        }
      },
      param.value());
}

// SQLite's numbered parameters ?1..?n as PostgreSQL's $1..$n (the shared SQL has no '?' in
// its literals).
std::string DollarParams(const std::string& sql) {
  std::string converted = sql;
  for (size_t i = 0; i + 1 < converted.size(); ++i) {
    if (converted[i] == '?' && std::isdigit(static_cast<unsigned char>(converted[i + 1]))) {
      converted[i] = '$';
    }
  }
  return converted;
}

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

 private:
  PGresult* result_;
};

// Whether a failed call failed because the server is gone rather than because of the call: the
// connection broke, or the server refused it as shutting down, starting or in crash recovery
// (SQLSTATE class 08, connection exception; 57P01-57P03, operator intervention).
bool ServerGone(PGconn* db, PGresult* result) {
  if (PQstatus(db) != CONNECTION_OK) return true;
  const char* state = result ? PQresultErrorField(result, PG_DIAG_SQLSTATE) : nullptr;
  if (!state) return result == nullptr;
  const std::string code = state;
  return code.rfind("08", 0) == 0 || code == "57P01" || code == "57P02" || code == "57P03";
}

void Check(PGconn* db, PGresult* result) {
  const ExecStatusType status = PQresultStatus(result);
  if (status == PGRES_COMMAND_OK || status == PGRES_TUPLES_OK) return;
  const std::string message =
      std::string("PostgreSQL: ") + (result ? PQresultErrorMessage(result) : PQerrorMessage(db));
  if (ServerGone(db, result)) throw StoreUnavailable(message);
  throw PostgresError(message);
}

// Runs `sql` with text parameters $1..$n; throws PostgresError unless it succeeded.
Result Run(PGconn* db, const std::string& sql, const std::vector<SqlValue>& params = {}) {
  std::vector<std::optional<std::string>> texts;
  texts.reserve(params.size());
  for (const SqlValue& param : params) texts.push_back(Text(param));
  std::vector<const char*> values;
  values.reserve(texts.size());
  for (const auto& text : texts) values.push_back(text ? text->c_str() : nullptr);
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

// SqlSession on one PostgreSQL connection.
class PostgresSession : public SqlSession {
 public:
  explicit PostgresSession(PGconn* db) : db_(db) {}

  void Query(const std::string& sql, const std::vector<SqlValue>& params,
             const std::function<void(const SqlRow&)>& each_row) override {
    const Result rows = Run(db_, DollarParams(sql), params);
    for (int row = 0; row < rows.rows(); ++row) each_row(Row(rows, row));
  }

  int64_t Execute(const std::string& sql, const std::vector<SqlValue>& params) override {
    return Run(db_, DollarParams(sql), params).affected();
  }

 private:
  class Row : public SqlRow {
   public:
    Row(const Result& rows, int row) : rows_(rows), row_(row) {}
    bool IsNull(int column) const override { return rows_.IsNull(row_, column); }
    std::string Text(int column) const override { return rows_.Text(row_, column); }
    int64_t Int(int column) const override { return rows_.Int(row_, column); }
    double Double(int column) const override { return rows_.Double(row_, column); }

   private:
    const Result& rows_;
    int row_;
  };

  PGconn* db_;
};

PGconn* Connect(const std::string& url) {
  PGconn* db = PQconnectdb(url.c_str());
  if (PQstatus(db) != CONNECTION_OK) {
    const std::string message = PQerrorMessage(db);
    PQfinish(db);
    throw StoreUnavailable("cannot connect to PostgreSQL: " + message);
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
    : SqlJobStore(Dialect()),
      url_(url),
      max_connections_(std::max(1, max_connections)) {
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
  return static_cast<int>(SchemaMigrations(Dialect()).size());
}

PostgresJobStore::Lease PostgresJobStore::Borrow() {
  std::unique_lock<std::mutex> lock(pool_mutex_);
  pool_available_.wait(lock, [this] { return !idle_.empty() || open_ < max_connections_; });
  while (!idle_.empty()) {
    PGconn* db = idle_.back();
    idle_.pop_back();
    // A server that stopped or restarted since this connection was last used closed it (and
    // said so): reading what is waiting finds out without a round trip, and a fresh
    // connection replaces it instead of failing the call.
    if (PQconsumeInput(db) != 0 && PQstatus(db) == CONNECTION_OK) return Lease(*this, db);
    PQfinish(db);
    --open_;
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
  const std::vector<std::string> migrations = SchemaMigrations(Dialect());
  for (int next = version; next < SchemaVersion(); ++next) {
    PGresult* raw = PQexec(db.get(), migrations[next].c_str());  // several statements: no parameters
    Result result(raw);
    Check(db.get(), raw);
    Run(db.get(), "UPDATE omnirig_schema SET version = $1", {next + 1});
  }
  transaction.Commit();
}

void PostgresJobStore::WithReader(const std::function<void(SqlSession&)>& work) {
  WithWriter(work);  // any pooled connection reads and writes
}

void PostgresJobStore::WithWriter(const std::function<void(SqlSession&)>& work) {
  Lease db = Borrow();
  PostgresSession session(db.get());
  work(session);
}

bool PostgresJobStore::InTransaction(const std::function<bool(SqlSession&)>& work) {
  Lease db = Borrow();
  Transaction transaction(db.get());
  PostgresSession session(db.get());
  if (!work(session)) return false;
  transaction.Commit();
  return true;
}

// Delivered when the transaction commits, to every process listening (WaitForQueueChange).
void PostgresJobStore::OnJobsQueued(SqlSession& db) {
  db.Execute(std::string("NOTIFY ") + kChannel);
}

JobRecord PostgresJobStore::CreateJob(const std::string& type, const std::string& dataset_id,
                                      const std::string& params) {
  const JobRecord job = NewJob(type, dataset_id, params);
  // One statement, one implicit transaction: the notification goes out when the row commits.
  WithWriter([&](SqlSession& db) {
    db.Execute(std::string("WITH queued AS (") + kInsertJob +
                   " RETURNING id) SELECT pg_notify('omnirig_jobs', id) FROM queued",
               {job.id, type, dataset_id, params, job.created_at});
  });
  return job;
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
