#include "server/commands.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>

#include <cstdlib>
#include <iostream>

#include "engine/util/check.h"
#include "server/cli/args.h"
#include "server/service.h"

#ifndef OMNIRIG_WEB_DIR
#define OMNIRIG_WEB_DIR "web"
#endif

namespace omnirig::server {
namespace {

void DeclareOptions(cli::ArgParser& parser) {
  parser.AddOption("host", "127.0.0.1", "address to bind (non-loopback needs --token)");
  parser.AddOption("port", "8080", "TCP port (0 picks a free one, printed on stdout)");
  parser.AddOption("data", "./data", "folder holding the SQLite database and all files");
  parser.AddOption("database", "",
                   "job store shared with other machines: postgresql://USER@HOST:PORT/DB "
                   "(default: SQLite under --data; see docs/multi-machine.md)");
  parser.AddOption("web", OMNIRIG_WEB_DIR, "folder of the web page's static files");
  parser.AddOption("token", "",
                   "bearer token required for every API call (default: $OMNIRIG_TOKEN)");
  parser.AddOption("workers", std::to_string(DefaultWorkers()),
                   "jobs run at the same time (half the cores by default; 0: API only, jobs "
                   "run by `omnirig worker` processes)");
  parser.AddOption("http-threads", "256",
                   "HTTP threads: one per open connection (keep-alive clients and event streams "
                   "each hold one); connections beyond wait for a thread");
  parser.AddOption("max-connections", "",
                   "open HTTP connections at most; beyond, a new one gets 503 and is closed "
                   "(default: the open-file limit, raised to its hard limit at start, less a "
                   "reserve for SQLite, uploads and artifacts; at most 4096; 0: no cap)");
  parser.AddOption("worker-sched", "normal",
                   "scheduling of job threads: 'normal' or 'idle' (SCHED_IDLE: jobs run only "
                   "when nothing else on the machine wants the CPU)");
  parser.AddOption("max-file-mb", "256", "largest image upload, MB");
  parser.AddOption("max-video-mb", "8192", "largest video upload, MB");
  parser.AddOption("max-chunk-mb", "64",
                   "largest chunk of a resumable upload (PUT with Content-Range), MB");
  parser.AddOption("max-dataset-mb", "8192", "largest dataset, MB");
  parser.AddOption("max-images", "20000", "most images in one dataset");
  parser.AddOption("max-queued-jobs", "1000", "most jobs waiting in the queue (then 503)");
  DeclareWorkerOptions(parser, "workers");
}

int64_t Megabytes(const cli::ArgParser& parser, const std::string& name) {
  return static_cast<int64_t>(parser.GetDouble(name) * 1024 * 1024);
}

ServiceOptions ToOptions(const cli::ArgParser& parser) {
  ServiceOptions options;
  options.host = parser.Get("host");
  options.port = parser.GetInt("port");
  options.data_dir = parser.Get("data");
  options.database = parser.Get("database");
  options.web_dir = parser.Get("web");
  options.token = parser.Get("token");
  if (options.token.empty() && std::getenv("OMNIRIG_TOKEN")) {
    options.token = std::getenv("OMNIRIG_TOKEN");
  }
  options.workers = WorkerOptionsFromArgs(parser, parser.GetInt("workers"));
  const std::string scheduling = parser.Get("worker-sched");
  OMNIRIG_CHECK(scheduling == "idle" || scheduling == "normal",
                "--worker-sched must be 'idle' or 'normal', got '" << scheduling << "'");
  options.workers.idle_scheduling = scheduling == "idle";
  options.http_threads = parser.GetInt("http-threads");
  // Raised here, before anything opens files: the default cap is what the raised limit allows.
  const int64_t open_file_limit = RaiseOpenFileLimit();
  options.max_connections = parser.Get("max-connections").empty()
                                ? DefaultMaxConnections(open_file_limit, options.http_threads)
                                : parser.GetInt("max-connections");
  options.max_file_bytes = Megabytes(parser, "max-file-mb");
  options.max_video_bytes = Megabytes(parser, "max-video-mb");
  options.max_chunk_bytes = Megabytes(parser, "max-chunk-mb");
  options.max_dataset_bytes = Megabytes(parser, "max-dataset-mb");
  options.max_images_per_dataset = parser.GetInt("max-images");
  options.max_queued_jobs = parser.GetInt("max-queued-jobs");
  options.min_free_bytes = Megabytes(parser, "min-free-mb");
  return options;
}

int signal_pipe[2] = {-1, -1};

extern "C" void OnStopSignal(int signal_number) {
  const char byte = static_cast<char>(signal_number);
  [[maybe_unused]] const ssize_t ignored = ::write(signal_pipe[1], &byte, 1);
}

}  // namespace

void DeclareWorkerOptions(cli::ArgParser& parser, const std::string& count_option) {
  parser.AddOption("threads-per-job", "",
                   "solver threads per job (default: cores / --" + count_option + ")");
  parser.AddOption("lease-seconds", "30",
                   "a running job's lease, renewed every third of it; a worker silent this long "
                   "loses the job to another");
  parser.AddOption("max-attempts", "3",
                   "runs a job may start before crashes or expired leases make it fail "
                   "('interrupted')");
  // Normal priority: a job's thread that yields to every other process on a busy machine
  // crawls (docs/http.md, Workers), and a worker process has no HTTP threads to yield to.
  parser.AddOption("worker-nice", "0", "niceness of job threads (0-19)");
  parser.AddOption("min-free-mb", "256",
                   "free disk space to keep under --data: uploads beyond get 507, a job that "
                   "leaves less fails with 'disk_full' and its outputs are removed");
  parser.AddOption("drain-timeout", "20",
                   "seconds SIGTERM waits for running jobs before re-queuing them");
}

WorkerPoolOptions WorkerOptionsFromArgs(const cli::ArgParser& parser, int num_workers) {
  WorkerPoolOptions options;
  options.num_workers = num_workers;
  options.threads_per_job = parser.Get("threads-per-job").empty()
                                ? DefaultThreadsPerJob(num_workers)
                                : parser.GetInt("threads-per-job");
  options.lease_s = parser.GetDouble("lease-seconds");
  options.max_attempts = parser.GetInt("max-attempts");
  options.nice = parser.GetInt("worker-nice");
  options.min_free_bytes = Megabytes(parser, "min-free-mb");
  return options;
}

void InstallStopSignalHandlers() {
  if (::pipe2(signal_pipe, O_CLOEXEC) != 0) throw std::runtime_error("cannot create a pipe");
  struct sigaction action {};
  action.sa_handler = OnStopSignal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  sigaction(SIGTERM, &action, nullptr);
  sigaction(SIGINT, &action, nullptr);
  signal(SIGPIPE, SIG_IGN);
}

// Waits in poll() before reading: ThreadSanitizer runs a signal handler at once only in a call
// it knows to block (poll, not read), else it defers it to the thread's next intercepted call;
// a SIGTERM that landed on this thread while it sat in read() (restarted: SA_RESTART) was never
// handled, and the server under TSan did not stop (scripts/tsan.sh, tests/server_crash).
int WaitThenDrain(const std::string& who, double timeout_s,
                  const std::function<int(double timeout_s)>& drain) {
  pollfd ready{signal_pipe[0], POLLIN, 0};
  while (::poll(&ready, 1, -1) < 0 && errno == EINTR) {
  }
  char received = 0;
  while (::read(signal_pipe[0], &received, 1) < 0 && errno == EINTR) {
  }
  std::cerr << who << ": " << (received == SIGTERM ? "SIGTERM" : "SIGINT") << ": draining (up to "
            << timeout_s << " s)" << std::endl;
  const int requeued = drain(timeout_s);
  std::cerr << who << ": stopped; " << requeued << " running job(s) handed back to the queue"
            << std::endl;
  return 0;
}

int ServeCommand(const std::vector<std::string>& args,
                 const std::vector<api::JobType>& extra_job_types) {
  cli::ArgParser parser("serve",
                        "Runs the omnirig HTTP service: REST API under /api/v1, job workers, "
                        "/metrics and the web page.");
  DeclareOptions(parser);
  if (!parser.Parse(args)) return parser.exit_code();
  ServiceOptions options = ToOptions(parser);
  options.extra_job_types = extra_job_types;
  const double drain_timeout_s = parser.GetDouble("drain-timeout");

  // SIGTERM/SIGINT write to a pipe that this thread waits on. A handler (rather than a blocked
  // mask and sigwait) works whichever thread the kernel picks, including threads that libraries
  // start before this point.
  InstallStopSignalHandlers();
  Service service(options);
  const int port = service.Start();
  std::cout << "omnirig listening on http://" << options.host << ":" << port << std::endl;
  std::cerr << "omnirig: at most " << options.max_connections << " open connections (0: no cap)"
            << std::endl;
  return WaitThenDrain("omnirig", drain_timeout_s,
                       [&service](double timeout_s) { return service.Drain(timeout_s); });
}

int ServeCommand(const std::vector<std::string>& args) { return ServeCommand(args, {}); }

}  // namespace omnirig::server
