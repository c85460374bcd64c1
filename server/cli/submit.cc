// `omnirig submit`: placeholder until its issue lands.

#include <iostream>

#include "server/cli/commands.h"

namespace omnirig::cli {

int RunSubmit(const Args&) {
  std::cerr << "omnirig submit: not available yet\n";
  return 1;
}

}  // namespace omnirig::cli
