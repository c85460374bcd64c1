#include "server/commands.h"

#include <iostream>

#include "api/job_types.h"
#include "engine/util/check.h"
#include "server/cli/args.h"
#include "server/metrics.h"
#include "server/service.h"
#include "server/worker_pool.h"
#include "storage/postgres_job_store.h"

namespace omnirig::server {

int WorkerCommand(const std::vector<std::string>& args,
                  const std::vector<api::JobType>& extra_job_types) {
  cli::ArgParser parser("worker",
                        "Runs jobs from a PostgreSQL job store shared with `omnirig serve "
                        "--database` and other workers, on this or other machines. Serves no "
                        "HTTP.");
  parser.AddOption("database", "", "the shared job store: postgresql://USER@HOST:PORT/DB");
  parser.AddOption("data", "./data",
                   "the shared data folder, mounted at the same path on every machine");
  parser.AddOption("threads", std::to_string(DefaultWorkers()),
                   "jobs run at the same time (half the cores by default)");
  parser.AddOption("worker-id", "", "name in leases, heartbeats and /metrics (default: HOST:PID)");
  DeclareWorkerOptions(parser, "threads");
  if (!parser.Parse(args)) return parser.exit_code();
  const std::string database = parser.Get("database");
  if (!storage::IsPostgresUrl(database)) {
    throw InvalidArgument("--database must be a postgresql:// URL (workers share its queue)");
  }
  const int num_workers = parser.GetInt("threads");
  OMNIRIG_CHECK(num_workers >= 1, "--threads must be at least 1");
  WorkerPoolOptions options = WorkerOptionsFromArgs(parser, num_workers);
  options.worker_id = parser.Get("worker-id");
  // This process serves no HTTP: job threads need not yield to anything.
  options.idle_scheduling = false;
  // NOTIFY wakes idle workers at once; the poll only covers a lost notification.
  options.idle_poll_s = 5;
  options.Check();
  const double drain_timeout_s = parser.GetDouble("drain-timeout");

  InstallStopSignalHandlers();
  api::JobTypes job_types;
  api::AddBuiltinJobTypes(&job_types);
  for (const api::JobType& type : extra_job_types) job_types.Add(type);
  const storage::DataDir data_dir(parser.Get("data"));
  storage::PostgresJobStore store(database);
  Metrics metrics;
  WorkerPool pool(store, data_dir, job_types, metrics, options);
  pool.Start();
  std::cout << "omnirig worker " << pool.worker_id() << " running " << options.num_workers
            << " job(s) at a time" << std::endl;
  return WaitThenDrain("omnirig worker", drain_timeout_s,
                       [&pool](double timeout_s) { return pool.Drain(timeout_s); });
}

int WorkerCommand(const std::vector<std::string>& args) { return WorkerCommand(args, {}); }

}  // namespace omnirig::server
