#pragma once
// JobStore on PostgreSQL (libpq), shared by API servers and workers on several machines: one
// transactional source of truth for records and the queue. Workers claim with
// SELECT ... FOR UPDATE SKIP LOCKED (two claims never wait on or share a row), and every change
// that queues a job sends NOTIFY omnirig_jobs, so idle workers wake at once instead of polling.
//
// The schema has the same versions and migrations as the SQLite store (SchemaMigrations in
// sql_job_store.h, in PostgreSQL's type names); the version lives in the table omnirig_schema
// and migrations run under an advisory lock, so processes starting together migrate once.
// Lease expiry is compared with the database server's clock, so the machines' clocks need not
// agree. The methods whose SQL SQLite runs as written are SqlJobStore's (sql_job_store.h).

#include <condition_variable>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

#include "storage/sql_job_store.h"

typedef struct pg_conn PGconn;

namespace omnirig::storage {

// A statement the server refused. A server that cannot be reached (stopped, restarting, cut
// off) throws StoreUnavailable (job_store.h) instead.
class PostgresError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// True for "postgresql://..." and "postgres://..." connection URLs.
bool IsPostgresUrl(const std::string& url);

class PostgresJobStore : public SqlJobStore {
 public:
  // Connects to `url` (a libpq connection URL, postgresql://USER@HOST:PORT/DB) and applies
  // pending migrations. At most `max_connections` connections are opened, on demand.
  explicit PostgresJobStore(const std::string& url, int max_connections = 8);
  ~PostgresJobStore() override;

  static int SchemaVersion();

  JobRecord CreateJob(const std::string& type, const std::string& dataset_id,
                      const std::string& params) override;
  bool NotifiesQueueChanges() const override { return true; }
  bool WaitForQueueChange(double timeout_s) override;
  std::string IntegrityCheck() override;

 protected:
  void WithReader(const std::function<void(SqlSession&)>& work) override;
  void WithWriter(const std::function<void(SqlSession&)>& work) override;
  bool InTransaction(const std::function<bool(SqlSession&)>& work) override;
  void OnJobsQueued(SqlSession& db) override;

 private:
  class Lease;
  Lease Borrow();
  // Closes the idle connections and the listener (the destructor, a failed construction).
  void CloseConnections();
  void Migrate();

  std::string url_;
  int max_connections_;
  std::mutex pool_mutex_;
  std::condition_variable pool_available_;
  std::vector<PGconn*> idle_;
  int open_ = 0;
  std::mutex listener_mutex_;
  PGconn* listener_ = nullptr;  // LISTEN omnirig_jobs, opened by the first wait
};

}  // namespace omnirig::storage
