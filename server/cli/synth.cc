// `omnirig synth`: placeholder until its issue lands.

#include <iostream>

#include "server/cli/commands.h"

namespace omnirig::cli {

int RunSynth(const Args&) {
  std::cerr << "omnirig synth: not available yet\n";
  return 1;
}

}  // namespace omnirig::cli
