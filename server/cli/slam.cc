// `omnirig slam`: placeholder until its issue lands.

#include <iostream>

#include "server/cli/commands.h"

namespace omnirig::cli {

int RunSlam(const Args&) {
  std::cerr << "omnirig slam: not available yet\n";
  return 1;
}

}  // namespace omnirig::cli
