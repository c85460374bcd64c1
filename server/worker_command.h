#pragma once
// `omnirig worker`: runs jobs from a shared PostgreSQL job store, with no HTTP (see
// docs/multi-machine.md). Waits for SIGTERM/SIGINT, then drains like `omnirig serve`.

#include <string>
#include <vector>

namespace omnirig::server {

// Returns the process exit code. Prints "omnirig worker ID running N job(s) at a time" on
// stdout once it takes jobs.
int WorkerCommand(const std::vector<std::string>& args);

}  // namespace omnirig::server
