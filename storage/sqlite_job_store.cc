#include "storage/sqlite_job_store.h"

#include <type_traits>

namespace omnirig::storage {
namespace {

// SQLite's dialect; the jobs' insertion order is the rowid.
SqlDialect Dialect() {
  return SqlDialect{/*byte_order=*/"", /*lock_row=*/"", /*insertion_order=*/"rowid",
                    /*skip_locked=*/"",
                    /*now=*/"((julianday('now') - 2440587.5) * 86400.0)",
                    /*real_type=*/"REAL", /*int64_type=*/"INTEGER",
                    /*insertion_order_column=*/""};
}

// SqlSession on one SQLite connection; statements come from its cache.
class SqliteSession : public SqlSession {
 public:
  explicit SqliteSession(Connection& db) : db_(db) {}

  void Query(const std::string& sql, const std::vector<SqlValue>& params,
             const std::function<void(const SqlRow&)>& each_row) override {
    Statement statement(db_, sql);
    Bind(statement, params);
    const Row row(statement);
    while (statement.Step()) each_row(row);
  }

  int64_t Execute(const std::string& sql, const std::vector<SqlValue>& params) override {
    Statement statement(db_, sql);
    Bind(statement, params);
    statement.Run();
    return db_.changes();
  }

 private:
  class Row : public SqlRow {
   public:
    explicit Row(const Statement& statement) : statement_(statement) {}
    bool IsNull(int column) const override { return statement_.IsNull(column); }
    std::string Text(int column) const override { return statement_.Text(column); }
    int64_t Int(int column) const override { return statement_.Int(column); }
    double Double(int column) const override { return statement_.Double(column); }

   private:
    const Statement& statement_;
  };

  static void Bind(Statement& statement, const std::vector<SqlValue>& params) {
    for (int i = 0; i < static_cast<int>(params.size()); ++i) {
      std::visit(
          [&](const auto& value) {
            if constexpr (std::is_same_v<std::decay_t<decltype(value)>, std::monostate>) {
              statement.BindNull(i + 1);
            } else {
              statement.Bind(i + 1, value);
            }
          },
          params[i].value());
    }
  }

  Connection& db_;
};

}  // namespace

SqliteJobStore::SqliteJobStore(const std::string& path, int num_readers)
    : SqlJobStore(Dialect()),
      path_(path) {
  writer_ = std::make_unique<Connection>(path);
  Migrate();
  for (int i = 0; i < std::max(1, num_readers); ++i) {
    idle_readers_.push_back(std::make_unique<Connection>(path));
  }
}

SqliteJobStore::~SqliteJobStore() = default;

int SqliteJobStore::SchemaVersion() {
  return static_cast<int>(SchemaMigrations(Dialect()).size());
}

// On a reader connection borrowed from the pool, given back however `work` ends.
void SqliteJobStore::WithReader(const std::function<void(SqlSession&)>& work) {
  std::unique_lock<std::mutex> lock(readers_mutex_);
  readers_available_.wait(lock, [this] { return !idle_readers_.empty(); });
  struct Lease {
    SqliteJobStore* store;
    std::unique_ptr<Connection> connection;
    ~Lease() {
      std::lock_guard<std::mutex> lock(store->readers_mutex_);
      store->idle_readers_.push_back(std::move(connection));
      store->readers_available_.notify_one();
    }
  } lease{this, std::move(idle_readers_.back())};
  idle_readers_.pop_back();
  lock.unlock();
  SqliteSession session(*lease.connection);
  work(session);
}

void SqliteJobStore::WithWriter(const std::function<void(SqlSession&)>& work) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  SqliteSession session(*writer_);
  work(session);
}

bool SqliteJobStore::InTransaction(const std::function<bool(SqlSession&)>& work) {
  std::lock_guard<std::mutex> lock(writer_mutex_);
  Transaction transaction(*writer_);
  SqliteSession session(*writer_);
  if (!work(session)) return false;
  transaction.Commit();
  return true;
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
  const std::vector<std::string> migrations = SchemaMigrations(Dialect());
  for (int next = version; next < SchemaVersion(); ++next) {
    Transaction transaction(*writer_);
    writer_->Exec(migrations[next]);
    writer_->Exec("PRAGMA user_version = " + std::to_string(next + 1));
    transaction.Commit();
  }
}

JobRecord SqliteJobStore::CreateJob(const std::string& type, const std::string& dataset_id,
                                    const std::string& params) {
  const JobRecord job = NewJob(type, dataset_id, params);
  WithWriter([&](SqlSession& db) {
    db.Execute(kInsertJob, {job.id, type, dataset_id, params, job.created_at});
  });
  return job;
}

std::string SqliteJobStore::IntegrityCheck() {
  return Read([&](SqlSession& db) {
    std::string problems;
    db.Query("PRAGMA integrity_check", {}, [&](const SqlRow& row) {
      if (!problems.empty()) problems += "; ";
      problems += row.Text(0);
    });
    return problems;
  });
}

}  // namespace omnirig::storage
