#include "server/cli/job_options.h"

#include <iomanip>
#include <iostream>
#include <sstream>

#include "server/cli/files.h"

namespace omnirig::cli {

using nlohmann::json;

void AddBoardOptions(const BoardDefaults& defaults, ArgParser* parser) {
  parser->AddOption("board", "checkerboard", "board type: checkerboard or charuco");
  parser->AddOption("cols", defaults.cols, "inner corners per row");
  parser->AddOption("rows", defaults.rows, "inner corners per column");
  parser->AddOption("square-mm", defaults.square_mm, "square size in millimetres");
  parser->AddOption("marker-mm", defaults.marker_mm, "ChArUco: marker size in millimetres");
  parser->AddOption("dictionary", defaults.dictionary,
                    "ChArUco: OpenCV predefined ArUco dictionary number");
}

json BoardParams(const ArgParser& parser) {
  json board = {{"type", parser.Get("board")},
                {"cols", parser.GetInt("cols")},
                {"rows", parser.GetInt("rows")},
                {"square_size_mm", parser.GetDouble("square-mm")}};
  if (!parser.Get("marker-mm").empty()) board["marker_size_mm"] = parser.GetDouble("marker-mm");
  if (!parser.Get("dictionary").empty()) board["aruco_dictionary"] = parser.GetInt("dictionary");
  return board;
}

std::vector<std::string> SplitList(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::stringstream stream(text);
  for (std::string part; std::getline(stream, part, separator);) {
    if (!part.empty()) parts.push_back(part);
  }
  return parts;
}

// Each line goes to stderr in one write: a job reports from more than one thread (the dense
// job's pair figures come from its writer thread), and its lines must not interleave.
void PrintProgress(double fraction, const std::string& stage, const std::string& message) {
  std::ostringstream line;
  line << "[" << std::setw(3) << static_cast<int>(100.0 * fraction) << "%] " << stage
       << (message.empty() ? "" : " " + message) << "\n";
  std::cerr << line.str();
}

api::JobContext LocalJobContext(const std::filesystem::path& dir, int num_threads) {
  api::JobContext context;
  context.job_id = "cli";
  context.dataset_dir = dir;
  context.image_names = ListPairImages(dir);
  context.num_threads = num_threads;
  context.progress.report = PrintProgress;
  context.log = [](const std::string& line) { std::cerr << line + "\n"; };
  return context;
}

void AddCacheDirOption(ArgParser* parser) {
  parser->AddOption("cache-dir", "",
                    "folder for the rig's rectification tables kept across runs (default: "
                    "OUTDIR/../.omnirig-cache; \"none\": not kept)");
}

std::filesystem::path CacheDirFromArgs(const ArgParser& parser,
                                       const std::filesystem::path& out_dir) {
  const std::string given = parser.Get("cache-dir");
  if (given == "none") return {};
  if (!given.empty()) return given;
  std::filesystem::path out = std::filesystem::absolute(out_dir).lexically_normal();
  if (out.filename().empty()) out = out.parent_path();  // "OUTDIR/"
  return out.parent_path() / ".omnirig-cache";
}

}  // namespace omnirig::cli
