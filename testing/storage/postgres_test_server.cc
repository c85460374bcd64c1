#include "testing/storage/postgres_test_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <libpq-fe.h>
#include <netinet/in.h>
#include <pwd.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace omnirig::storage::testing {
namespace fs = std::filesystem;
namespace {

fs::path FindBinDir() {
  if (const char* bin = std::getenv("OMNIRIG_PG_BIN")) return bin;
  for (const char* version : {"15", "16", "17", "14", "13"}) {
    const fs::path dir = fs::path("/usr/lib/postgresql") / version / "bin";
    if (fs::exists(dir / "initdb")) return dir;
  }
  throw std::runtime_error(
      "PostgreSQL server binaries not found under /usr/lib/postgresql/*/bin (install the Debian "
      "package `postgresql`, or set OMNIRIG_PG_BIN)");
}

// Commands run as `postgres` when this process is root: initdb and postgres refuse root.
std::vector<std::string> AsServerUser(std::vector<std::string> argv) {
  if (::geteuid() != 0) return argv;
  std::vector<std::string> wrapped = {"runuser", "-u", "postgres", "--"};
  wrapped.insert(wrapped.end(), argv.begin(), argv.end());
  return wrapped;
}

std::string ShellQuote(const std::string& text) {
  std::string quoted = "'";
  for (char c : text) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

// Runs `argv` with stdout and stderr appended to `log`; returns its exit status.
int RunLogged(const std::vector<std::string>& argv, const fs::path& log) {
  std::vector<char*> args;
  for (const std::string& arg : argv) args.push_back(const_cast<char*>(arg.c_str()));
  args.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (fd >= 0) {
      ::dup2(fd, 1);
      ::dup2(fd, 2);
    }
    ::execvp(args[0], args.data());
    ::_exit(127);
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// A loopback port free right now (the kernel's pick); the server binds it a moment later and
// the caller retries with another if something took it in between.
int FreeLoopbackPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  address.sin_port = 0;
  socklen_t length = sizeof(address);
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length) != 0) {
    if (fd >= 0) ::close(fd);
    throw std::runtime_error("cannot find a free loopback port");
  }
  const int port = ntohs(address.sin_port);
  ::close(fd);
  return port;
}

}  // namespace

PostgresTestServer::PostgresTestServer(const PostgresTestServerOptions& options)
    : bin_dir_(FindBinDir()) {
  std::string pattern = (fs::temp_directory_path() / "omnirig-pg-XXXXXX").string();
  if (!::mkdtemp(pattern.data())) throw std::runtime_error("cannot create a temporary folder");
  dir_ = pattern;
  if (::geteuid() == 0) {
    const passwd* user = ::getpwnam("postgres");
    if (!user) throw std::runtime_error("no `postgres` system user to run PostgreSQL as");
    if (::chown(dir_.c_str(), user->pw_uid, user->pw_gid) != 0) {
      throw std::runtime_error("cannot hand " + dir_.string() + " to the postgres user");
    }
  }
  StartReaper();
  const fs::path data = dir_ / "data";
  const fs::path log = dir_ / "commands.log";       // written by this process
  const fs::path server_log = dir_ / "server.log";  // written by the server's user
  if (RunLogged(AsServerUser({(bin_dir_ / "initdb").string(), "-D", data.string(), "-A", "trust",
                              "-U", "postgres", "-E", "UTF8", "--locale=C", "--no-sync"}),
                log) != 0) {
    const std::string text = ReadFile(log);
    Stop();
    throw std::runtime_error("initdb failed:\n" + text);
  }
  fsync_ = options.fsync;
  for (int attempt = 0; attempt < 5; ++attempt) {
    port_ = FreeLoopbackPort();
    if (PgCtlStart() == 0) return;
  }
  const std::string text = ReadFile(log) + ReadFile(server_log);
  Stop();
  throw std::runtime_error("PostgreSQL did not start:\n" + text);
}

int PostgresTestServer::PgCtlStart() {
  const std::string server_options =
      "-p " + std::to_string(port_) + " -k " + dir_.string() +
      " -c listen_addresses=127.0.0.1 -c max_connections=200 -c fsync=" + (fsync_ ? "on" : "off") +
      (fsync_ ? "" : " -c synchronous_commit=off");
  return RunLogged(AsServerUser({(bin_dir_ / "pg_ctl").string(), "-D", (dir_ / "data").string(),
                                 "-l", (dir_ / "server.log").string(), "-o", server_options, "-w",
                                 "-t", "60", "start"}),
                   dir_ / "commands.log");
}

void PostgresTestServer::StopServer() {
  if (RunLogged(AsServerUser({(bin_dir_ / "pg_ctl").string(), "-D", (dir_ / "data").string(),
                              "-m", "fast", "-w", "stop"}),
                dir_ / "commands.log") != 0) {
    throw std::runtime_error("pg_ctl stop failed:\n" + ReadFile(dir_ / "commands.log"));
  }
}

void PostgresTestServer::KillServer() {
  const fs::path lock_file = dir_ / "data" / "postmaster.pid";
  const pid_t postmaster = static_cast<pid_t>(std::atol(ReadFile(lock_file).c_str()));
  if (postmaster <= 0) throw std::runtime_error("no running PostgreSQL to kill");
  // The back-ends first (read while the postmaster still parents them), then the postmaster.
  std::vector<pid_t> victims;
  for (const auto& entry : fs::directory_iterator("/proc")) {
    const pid_t pid = static_cast<pid_t>(std::atol(entry.path().filename().c_str()));
    if (pid <= 0) continue;
    std::istringstream stat(ReadFile(entry.path() / "stat"));
    std::string skip;
    pid_t parent = 0;
    // "PID (COMM) STATE PPID ...": COMM holds no spaces for postgres processes.
    if (stat >> skip >> skip >> skip >> parent && parent == postmaster) victims.push_back(pid);
  }
  victims.push_back(postmaster);
  for (const pid_t pid : victims) ::kill(pid, SIGKILL);
  // Gone once reaped, or a zombie where nothing reaps orphans: either way it holds nothing.
  for (const pid_t pid : victims) {
    while (true) {
      std::istringstream stat(ReadFile("/proc/" + std::to_string(pid) + "/stat"));
      std::string skip, state;
      if (!(stat >> skip >> skip >> state) || state == "Z") break;
      ::usleep(1000);  // a hang guard is ctest's timeout; the kernel ends a SIGKILLed process fast
    }
  }
  // A zombie's pid still answers kill(pid, 0): PostgreSQL would take its lock files (the data
  // folder's and the socket's) as a live server's.
  std::error_code ignored;
  fs::remove(lock_file, ignored);
  fs::remove(dir_ / (".s.PGSQL." + std::to_string(port_) + ".lock"), ignored);
}

void PostgresTestServer::StartServer() {
  if (PgCtlStart() != 0) {
    throw std::runtime_error("PostgreSQL did not start again:\n" +
                             ReadFile(dir_ / "commands.log") + ReadFile(dir_ / "server.log"));
  }
}

PostgresTestServer::~PostgresTestServer() { Stop(); }

void PostgresTestServer::StartReaper() {
  // Everything the child needs is built before fork(): after it, only exec-safe calls.
  std::string command;
  for (const std::string& arg :
       AsServerUser({(bin_dir_ / "pg_ctl").string(), "-D", (dir_ / "data").string(), "-m",
                     "immediate", "-w", "stop"})) {
    command += ShellQuote(arg) + " ";
  }
  command += ">/dev/null 2>&1; rm -rf " + ShellQuote(dir_.string());
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error("cannot create a pipe");
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    ::setsid();  // out of the test's process group: a group kill leaves it to clean up
    ::close(fds[1]);
    char byte;
    while (::read(fds[0], &byte, 1) != 0) {
    }
    ::execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::close(fds[0]);
  reaper_pid_ = pid;
  reaper_pipe_ = fds[1];
}

void PostgresTestServer::Stop() {
  if (reaper_pipe_ < 0) return;
  RunLogged(AsServerUser({(bin_dir_ / "pg_ctl").string(), "-D", (dir_ / "data").string(), "-m",
                          "fast", "-w", "stop"}),
            "/dev/null");
  ::close(reaper_pipe_);  // the reaper removes the folder
  reaper_pipe_ = -1;
  int status = 0;
  ::waitpid(reaper_pid_, &status, 0);
}

std::string PostgresTestServer::Url(const std::string& database) const {
  return "postgresql://postgres@127.0.0.1:" + std::to_string(port_) + "/" + database;
}

std::string PostgresTestServer::CreateDatabase() {
  const std::string name = "test_" + std::to_string(++databases_);
  PGconn* db = PQconnectdb(Url().c_str());
  std::unique_ptr<PGconn, void (*)(PGconn*)> closer(db, PQfinish);
  if (PQstatus(db) != CONNECTION_OK) {
    throw std::runtime_error(std::string("cannot connect: ") + PQerrorMessage(db));
  }
  PGresult* result = PQexec(db, ("CREATE DATABASE " + name).c_str());
  const bool ok = PQresultStatus(result) == PGRES_COMMAND_OK;
  const std::string error = PQresultErrorMessage(result);
  PQclear(result);
  if (!ok) throw std::runtime_error("CREATE DATABASE failed: " + error);
  return Url(name);
}

PostgresTestServer& SharedPostgresTestServer() {
  // A start that failed is not retried by every test: each reports the first failure.
  static std::string failure;
  static std::unique_ptr<PostgresTestServer> server = [] {
    try {
      return std::make_unique<PostgresTestServer>();
    } catch (const std::exception& e) {
      failure = e.what();
      return std::unique_ptr<PostgresTestServer>();
    }
  }();
  if (!server) throw std::runtime_error(failure);
  return *server;
}

}  // namespace omnirig::storage::testing
