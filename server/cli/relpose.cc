// `omnirig relpose`: placeholder until its issue lands.

#include <iostream>

#include "server/cli/commands.h"

namespace omnirig::cli {

int RunRelpose(const Args&) {
  std::cerr << "omnirig relpose: not available yet\n";
  return 1;
}

}  // namespace omnirig::cli
