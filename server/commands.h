#pragma once
// The subcommands that run the service (server/): `omnirig serve` (serve_command.cc), `omnirig
// worker` (worker_command.cc) and `omnirig store copy` (store_command.cc). Each takes the
// arguments after its name and returns the process exit code.

#include <functional>
#include <string>
#include <vector>

#include "server/cli/args.h"
#include "server/worker_pool.h"

namespace omnirig::server {

// SIGTERM and SIGINT, from any thread, wake WaitThenDrain; SIGPIPE is ignored. Shared by
// `omnirig serve` and `omnirig worker`.
void InstallStopSignalHandlers();
// Declares the job threads' options `omnirig serve` and `omnirig worker` both take
// (--threads-per-job, --lease-seconds, --max-attempts, --worker-nice, --min-free-mb,
// --drain-timeout); `count_option` names the command's own count of jobs run at once (serve's
// --workers, worker's --threads), which --threads-per-job divides the cores by.
void DeclareWorkerOptions(cli::ArgParser& parser, const std::string& count_option);
// Those options (DeclareWorkerOptions) for `num_workers` workers.
WorkerPoolOptions WorkerOptionsFromArgs(const cli::ArgParser& parser, int num_workers);
// Waits for SIGTERM or SIGINT, then calls `drain` with `timeout_s` (it returns the running jobs
// it handed back to the queue), logging both on stderr as `who`. Returns the exit code, 0.
int WaitThenDrain(const std::string& who, double timeout_s,
                  const std::function<int(double timeout_s)>& drain);

// Runs the service until SIGTERM or SIGINT, then drains. Prints "omnirig listening on
// http://HOST:PORT" on stdout once the port is bound (with --port 0 the line names the port the
// system chose). `extra_job_types`: ServiceOptions::extra_job_types (a test's own).
int ServeCommand(const std::vector<std::string>& args);
int ServeCommand(const std::vector<std::string>& args,
                 const std::vector<api::JobType>& extra_job_types);

// Runs jobs from a shared PostgreSQL job store, with no HTTP (see docs/multi-machine.md); waits
// for SIGTERM/SIGINT, then drains like `omnirig serve`. Prints "omnirig worker ID running N
// job(s) at a time" on stdout once it takes jobs. It runs the built-in job types and
// `extra_job_types` (a test's own).
int WorkerCommand(const std::vector<std::string>& args);
int WorkerCommand(const std::vector<std::string>& args,
                  const std::vector<api::JobType>& extra_job_types);

// `omnirig store copy --from sqlite:DIR --to postgresql://...`: moves a one-machine service's
// records (datasets, jobs, results, artifact records) into a shared PostgreSQL store (or back),
// so a team keeps its history when it grows to several machines.
int StoreCommand(const std::vector<std::string>& args);

}  // namespace omnirig::server
