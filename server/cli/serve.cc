// `omnirig serve`: the HTTP service (see server/serve_command.h).

#include "server/cli/commands.h"
#include "server/serve_command.h"

namespace omnirig::cli {

int RunServe(const Args& args) { return server::ServeCommand(args); }

}  // namespace omnirig::cli
