// omnirig: one executable, one subcommand per task.

#include <cstring>
#include <exception>
#include <iostream>
#include <string>

#include "engine/util/allocator.h"
#include "engine/util/check.h"
#include "server/cli/commands.h"
#include "server/commands.h"

namespace {

struct Command {
  const char* name;
  const char* summary;
  int (*run)(const omnirig::cli::Args&);
};

const Command kCommands[] = {
    {"serve", "run the HTTP service (REST API, job workers, web page)",
     omnirig::server::ServeCommand},
    {"worker", "run jobs from a PostgreSQL job store shared by several machines",
     omnirig::server::WorkerCommand},
    {"store", "store copy: move a service's records from SQLite to PostgreSQL",
     omnirig::server::StoreCommand},
    {"synth", "render synthetic omnidirectional images with ground truth", omnirig::cli::RunSynth},
    {"calibrate", "calibrate one catadioptric camera from board images",
     omnirig::cli::RunCalibrate},
    {"relpose", "measure a stereo rig's metric relative pose from shared board views",
     omnirig::cli::RunRelpose},
    {"slam", "trajectory and metric map from a stereo sequence", omnirig::cli::RunSlam},
    {"stereo", "3D from stereo pairs of a calibrated rig (dense range panoramas and clouds)",
     omnirig::cli::RunStereo},
    {"submit", "upload a folder to a running server, run a job, download its results",
     omnirig::cli::RunSubmit},
    {"live", "play a recording against a server as a robot would (live slam job)",
     omnirig::cli::RunLive},
};

void PrintHelp() {
  std::cout << "usage: omnirig COMMAND [options]\n\n"
               "omnirig: calibration, stereo and SLAM for omnidirectional (catadioptric) "
               "stereo rigs.\n\ncommands:\n";
  for (const Command& command : kCommands) {
    std::cout << "  " << command.name << std::string(12 - std::strlen(command.name), ' ')
              << command.summary << "\n";
  }
  std::cout << "\n`omnirig COMMAND --help` explains every option of COMMAND.\n";
}

}  // namespace

int main(int argc, char** argv) {
  omnirig::ConfigureAllocator();  // before any thread starts
  if (argc < 2 || std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0) {
    PrintHelp();
    return argc < 2 ? 2 : 0;
  }
  const omnirig::cli::Args args(argv + 2, argv + argc);
  for (const Command& command : kCommands) {
    if (command.name != std::string(argv[1])) continue;
    try {
      return command.run(args);
    } catch (const omnirig::InvalidArgument& e) {
      std::cerr << "omnirig " << command.name << ": " << e.what() << "\n";
      return 2;
    } catch (const std::exception& e) {
      std::cerr << "omnirig " << command.name << ": error: " << e.what() << "\n";
      return 1;
    }
  }
  std::cerr << "omnirig: unknown command '" << argv[1] << "' (see omnirig --help)\n";
  return 2;
}
