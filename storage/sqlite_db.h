#pragma once
// A thin RAII layer over the SQLite C API: connections, prepared statements, transactions.
// Errors throw SqliteError (StoreFull when the disk is full); nothing here knows the schema.

#include <sqlite3.h>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "storage/job_store.h"

namespace omnirig::storage {

class Connection;

class SqliteError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class Statement {
 public:
  // Reuses the connection's prepared copy of `sql` (reset when this Statement ends): a status
  // poll then skips SQLite's parser and planner, most of its cost.
  Statement(Connection& connection, const std::string& sql);
  ~Statement();
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  // Parameters are 1-based, as in SQLite.
  Statement& Bind(int index, const std::string& value);
  Statement& Bind(int index, int64_t value);
  Statement& Bind(int index, double value);
  Statement& BindNull(int index);

  // Returns true while rows are available; false when done.
  bool Step();
  // Runs a statement that returns no rows.
  void Run();

  bool IsNull(int column) const;
  std::string Text(int column) const;
  int64_t Int(int column) const;
  double Double(int column) const;

 private:
  sqlite3* db_;
  sqlite3_stmt* statement_ = nullptr;
  bool* cached_in_use_ = nullptr;  // the cache entry's flag when borrowed from the cache
};

class Connection {
 public:
  // Opens (creating when missing) with WAL journaling, foreign keys on, synchronous=FULL (a
  // committed state change survives a power cut) and a busy timeout for concurrent writers.
  explicit Connection(const std::string& path);
  ~Connection();
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  void Exec(const std::string& sql);
  int64_t changes() const { return sqlite3_changes(db_); }

 private:
  friend class Statement;
  struct CachedStatement {
    sqlite3_stmt* statement = nullptr;
    bool in_use = false;
  };
  sqlite3* db_ = nullptr;
  std::unordered_map<std::string, CachedStatement> statements_;
};

// BEGIN IMMEDIATE on construction (takes the write lock up front, so read-then-write
// transactions never deadlock); rolls back unless Commit() was called.
class Transaction {
 public:
  explicit Transaction(Connection& connection);
  ~Transaction();
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;
  void Commit();

 private:
  Connection& connection_;
  bool done_ = false;
};

}  // namespace omnirig::storage
