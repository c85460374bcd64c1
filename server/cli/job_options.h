#pragma once
// What the subcommands that run a job's engine call in this process (calibrate, relpose, slam,
// stereo) share: the board options, the job context and progress lines on stderr.

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "api/job_types.h"
#include "server/cli/args.h"

namespace omnirig::cli {

// The defaults of the board options; "" for one the command requires.
struct BoardDefaults {
  std::string cols, rows, square_mm, marker_mm, dictionary;
};
// Declares --board, --cols, --rows, --square-mm, --marker-mm and --dictionary.
void AddBoardOptions(const BoardDefaults& defaults, ArgParser* parser);
// The job's "board" params from those options: the marker size and the dictionary only when
// they have a value (given, or a default).
nlohmann::json BoardParams(const ArgParser& parser);

// The non-empty parts of `text` between `separator`s ("a,,b" -> a, b).
std::vector<std::string> SplitList(const std::string& text, char separator);

// "[ 42%] stage message" on stderr.
void PrintProgress(double fraction, const std::string& stage, const std::string& message);

// A context for running a job here on DIR's image pairs (ListPairImages): job id "cli",
// progress (PrintProgress) and log lines on stderr.
api::JobContext LocalJobContext(const std::filesystem::path& dir, int num_threads);

// --cache-dir: where the CLI keeps files derived from inputs across runs (a rig's rectification
// tables, CACHE/rectification, as the service keeps them in DATA/cache).
void AddCacheDirOption(ArgParser* parser);
// The folder --cache-dir names; by default next to the outputs (OUTDIR's parent folder /
// ".omnirig-cache", so that runs into sibling output folders share it); empty for "none".
std::filesystem::path CacheDirFromArgs(const ArgParser& parser,
                                       const std::filesystem::path& out_dir);

}  // namespace omnirig::cli
