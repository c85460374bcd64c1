// `omnirig serve`: the HTTP service (see server/serve_command.h); `omnirig worker`: jobs only
// (server/worker_command.h); `omnirig store copy` (server/store_command.h).

#include "server/cli/commands.h"
#include "server/serve_command.h"
#include "server/store_command.h"
#include "server/worker_command.h"

namespace omnirig::cli {

int RunServe(const Args& args) { return server::ServeCommand(args); }

int RunWorker(const Args& args) { return server::WorkerCommand(args); }

int RunStore(const Args& args) { return server::StoreCommand(args); }

}  // namespace omnirig::cli
