#pragma once
// JobStore on one SQLite file in WAL mode: one writer connection (writes are serialised by
// SQLite anyway) and a small pool of reader connections, so status polls never wait behind a
// commit's fsync. The schema is versioned with PRAGMA user_version and migrated on open. The
// methods whose SQL PostgreSQL runs as written are SqlJobStore's (sql_job_store.h).

#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "storage/sql_job_store.h"
#include "storage/sqlite_db.h"

namespace omnirig::storage {

class SqliteJobStore : public SqlJobStore {
 public:
  // Opens or creates the database and applies pending migrations.
  explicit SqliteJobStore(const std::string& path, int num_readers = 4);
  ~SqliteJobStore() override;

  // The schema version this build writes (user_version after migration).
  static int SchemaVersion();

  JobRecord CreateJob(const std::string& type, const std::string& dataset_id,
                      const std::string& params) override;
  std::string IntegrityCheck() override;

 protected:
  void WithReader(const std::function<void(SqlSession&)>& work) override;
  void WithWriter(const std::function<void(SqlSession&)>& work) override;
  bool InTransaction(const std::function<bool(SqlSession&)>& work) override;

 private:
  void Migrate();

  std::string path_;
  std::mutex writer_mutex_;
  std::unique_ptr<Connection> writer_;
  std::mutex readers_mutex_;
  std::condition_variable readers_available_;
  std::vector<std::unique_ptr<Connection>> idle_readers_;
};

}  // namespace omnirig::storage
