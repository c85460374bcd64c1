// `omnirig calibrate`: placeholder until its issue lands.

#include <iostream>

#include "server/cli/commands.h"

namespace omnirig::cli {

int RunCalibrate(const Args&) {
  std::cerr << "omnirig calibrate: not available yet\n";
  return 1;
}

}  // namespace omnirig::cli
