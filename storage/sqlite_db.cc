#include "storage/sqlite_db.h"

namespace omnirig::storage {
namespace {

[[noreturn]] void Throw(sqlite3* db, const std::string& what) {
  const std::string message = what + ": " + (db ? sqlite3_errmsg(db) : "out of memory");
  if (db && sqlite3_errcode(db) == SQLITE_FULL) throw StoreFull(message);
  throw SqliteError(message);
}

sqlite3_stmt* Prepare(sqlite3* db, const std::string& sql) {
  sqlite3_stmt* statement = nullptr;
  if (sqlite3_prepare_v2(db, sql.c_str(), static_cast<int>(sql.size()), &statement, nullptr) !=
      SQLITE_OK) {
    Throw(db, "cannot prepare '" + sql + "'");
  }
  return statement;
}

}  // namespace

Statement::Statement(Connection& connection, const std::string& sql) : db_(connection.db_) {
  auto cached = connection.statements_.find(sql);
  if (cached != connection.statements_.end() && cached->second.in_use) {
    statement_ = Prepare(db_, sql);  // the same query nested in itself: a private copy
    return;
  }
  if (cached == connection.statements_.end()) {
    cached =
        connection.statements_.emplace(sql, Connection::CachedStatement{Prepare(db_, sql)}).first;
  }
  statement_ = cached->second.statement;
  cached->second.in_use = true;
  cached_in_use_ = &cached->second.in_use;
}

Statement::~Statement() {
  if (cached_in_use_) {
    // Ends the statement's read transaction and frees its bound values for the next user.
    sqlite3_reset(statement_);
    sqlite3_clear_bindings(statement_);
    *cached_in_use_ = false;
  } else {
    sqlite3_finalize(statement_);
  }
}

Statement& Statement::Bind(int index, const std::string& value) {
  if (sqlite3_bind_text(statement_, index, value.data(), static_cast<int>(value.size()),
                        SQLITE_TRANSIENT) != SQLITE_OK) {
    Throw(db_, "cannot bind");
  }
  return *this;
}

Statement& Statement::Bind(int index, int64_t value) {
  if (sqlite3_bind_int64(statement_, index, value) != SQLITE_OK) Throw(db_, "cannot bind");
  return *this;
}

Statement& Statement::Bind(int index, double value) {
  if (sqlite3_bind_double(statement_, index, value) != SQLITE_OK) Throw(db_, "cannot bind");
  return *this;
}

Statement& Statement::BindNull(int index) {
  if (sqlite3_bind_null(statement_, index) != SQLITE_OK) Throw(db_, "cannot bind");
  return *this;
}

bool Statement::Step() {
  const int status = sqlite3_step(statement_);
  if (status == SQLITE_ROW) return true;
  if (status == SQLITE_DONE) return false;
  Throw(db_, "statement failed");
}

void Statement::Run() {
  while (Step()) {
  }
}

bool Statement::IsNull(int column) const {
  return sqlite3_column_type(statement_, column) == SQLITE_NULL;
}

std::string Statement::Text(int column) const {
  const auto* text = sqlite3_column_text(statement_, column);
  const int size = sqlite3_column_bytes(statement_, column);
  return text ? std::string(reinterpret_cast<const char*>(text), static_cast<size_t>(size)) : "";
}

int64_t Statement::Int(int column) const { return sqlite3_column_int64(statement_, column); }

double Statement::Double(int column) const { return sqlite3_column_double(statement_, column); }

Connection::Connection(const std::string& path) {
  const int flags = SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX;
  if (sqlite3_open_v2(path.c_str(), &db_, flags, nullptr) != SQLITE_OK) {
    const std::string message = db_ ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close(db_);
    throw SqliteError("cannot open " + path + ": " + message);
  }
  sqlite3_busy_timeout(db_, 10000);
  Exec("PRAGMA journal_mode=WAL");
  Exec("PRAGMA synchronous=FULL");
  Exec("PRAGMA foreign_keys=ON");
}

Connection::~Connection() {
  for (auto& [sql, cached] : statements_) sqlite3_finalize(cached.statement);
  sqlite3_close(db_);
}

void Connection::Exec(const std::string& sql) {
  char* error = nullptr;
  if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &error) != SQLITE_OK) {
    const std::string message = "'" + sql.substr(0, 80) + "' failed: " + (error ? error : "unknown error");
    sqlite3_free(error);
    if (sqlite3_errcode(db_) == SQLITE_FULL) throw StoreFull(message);
    throw SqliteError(message);
  }
}

Transaction::Transaction(Connection& connection) : connection_(connection) {
  connection_.Exec("BEGIN IMMEDIATE");
}

Transaction::~Transaction() {
  if (!done_) {
    try {
      connection_.Exec("ROLLBACK");
    } catch (const std::exception&) {  // SqliteError or StoreFull
      // The transaction is already gone (e.g. SQLite rolled it back on an I/O error).
    }
  }
}

void Transaction::Commit() {
  connection_.Exec("COMMIT");
  done_ = true;
}

}  // namespace omnirig::storage
