#pragma once
// The `omnirig` subcommands of server/cli/ (serve, worker and store are server/commands.h's).
// Each takes the arguments after its name and returns the exit code.

#include <string>
#include <vector>

namespace omnirig::cli {

using Args = std::vector<std::string>;

int RunSynth(const Args& args);      // server/cli/synth.cc
int RunCalibrate(const Args& args);  // server/cli/calibrate.cc
int RunRelpose(const Args& args);    // server/cli/relpose.cc
int RunSlam(const Args& args);       // server/cli/slam.cc
int RunStereo(const Args& args);     // server/cli/stereo.cc
int RunSubmit(const Args& args);     // server/cli/submit.cc
int RunLive(const Args& args);       // server/cli/live.cc

}  // namespace omnirig::cli
