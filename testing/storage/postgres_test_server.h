#pragma once
// A real PostgreSQL server for tests and benches: a fresh cluster (initdb) in a temporary folder,
// listening on an ephemeral loopback port, run as the unprivileged `postgres` system user when
// the test runs as root (initdb refuses root). Stopped and removed by the destructor; a reaper
// process (its own session) does the same if the test process dies first (a crash, a ctest
// timeout's SIGKILL), so no server outlives its test.

#include <sys/types.h>

#include <filesystem>
#include <string>

namespace omnirig::storage::testing {

struct PostgresTestServerOptions {
  // fsync off: tests do not survive power cuts, and the cluster is thrown away. The bench turns
  // it on to measure what a real deployment does.
  bool fsync = false;
};

class PostgresTestServer {
 public:
  // Throws std::runtime_error (with the server's log) when the server cannot start.
  explicit PostgresTestServer(const PostgresTestServerOptions& options = {});
  ~PostgresTestServer();
  PostgresTestServer(const PostgresTestServer&) = delete;
  PostgresTestServer& operator=(const PostgresTestServer&) = delete;

  int port() const { return port_; }
  // postgresql://postgres@127.0.0.1:PORT/DATABASE
  std::string Url(const std::string& database = "postgres") const;
  // Creates a new, empty database and returns its URL.
  std::string CreateDatabase();

  // Outages for fault tests. StopServer: `pg_ctl stop -m fast` (clients are told and
  // disconnected). KillServer: SIGKILL to the server and every back-end, as a crash would; the
  // next start recovers from the write-ahead log. StartServer: back on the same port and data.
  void StopServer();
  void KillServer();
  void StartServer();

 private:
  void StartReaper();
  void Stop();
  int PgCtlStart();  // exit status of `pg_ctl start` on port_

  std::filesystem::path dir_;
  std::filesystem::path bin_dir_;
  int port_ = 0;
  bool fsync_ = false;
  int databases_ = 0;
  pid_t reaper_pid_ = -1;
  int reaper_pipe_ = -1;  // the write end; the reaper acts when it closes
};

// One server per test process, started on first use and stopped at exit.
PostgresTestServer& SharedPostgresTestServer();

}  // namespace omnirig::storage::testing
