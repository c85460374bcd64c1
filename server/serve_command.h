#pragma once
// `omnirig serve`: options -> ServiceOptions, start, wait for SIGTERM/SIGINT, drain.

#include <string>
#include <vector>

namespace omnirig::server {

// SIGTERM and SIGINT, from any thread, wake WaitForSignal (which returns the signal number).
// Shared by `omnirig serve` and `omnirig worker`.
void InstallStopSignalHandlers();
int WaitForSignal();

// Runs the service until SIGTERM or SIGINT; returns the process exit code. Prints
// "omnirig listening on http://HOST:PORT" on stdout once the port is bound (with --port 0 the
// line names the port the system chose).
int ServeCommand(const std::vector<std::string>& args);

}  // namespace omnirig::server
