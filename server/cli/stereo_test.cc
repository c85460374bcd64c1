// `omnirig stereo` end to end on one small rendered pair (label integration): the rig's
// rectification tables are kept in the cache folder, by default next to the outputs, and a
// later run reads them instead of building them.

#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "engine/synth/presets.h"
#include "server/cli/commands.h"

namespace omnirig::cli {
namespace {

namespace fs = std::filesystem;

// The tables files in `dir` (empty when it does not exist).
std::vector<fs::path> TablesFiles(const fs::path& dir) {
  std::vector<fs::path> files;
  std::error_code error;
  for (fs::directory_iterator it(dir, error), end; !error && it != end; it.increment(error)) {
    const std::string name = it->path().filename().string();
    if (name.rfind("rectification-v", 0) == 0) files.push_back(it->path());
  }
  return files;
}

ino_t Inode(const fs::path& path) {
  struct stat info {};
  return ::stat(path.c_str(), &info) == 0 ? info.st_ino : 0;
}

TEST(StereoCli, KeepsTheRectificationTablesNextToTheOutputsAndReadsThemLater) {
  synth::StereoSequenceOptions options;
  options.num_frames = 1;
  options.width = 640;
  options.height = 480;
  const synth::StereoSequence sequence = synth::MakeStereoSequence(options);
  const fs::path dir =
      fs::temp_directory_path() / ("omnirig_stereo_cli_" + std::to_string(std::random_device()()));
  for (int c = 0; c < 2; ++c) {
    fs::create_directories(dir / "data" / ("cam" + std::to_string(c)));
    cv::imwrite((dir / "data" / ("cam" + std::to_string(c)) / "a.png").string(),
                sequence.images[c][0]);
  }
  std::ofstream(dir / "rig.json") << api::RigToJson(sequence.rig).dump();
  const auto run = [&](const std::string& out, std::vector<std::string> extra) {
    std::vector<std::string> args = {"--rig", (dir / "rig.json").string(), (dir / "data").string(),
                                     "-o", (dir / "runs" / out).string()};
    args.insert(args.end(), extra.begin(), extra.end());
    return RunStereo(args);
  };

  ASSERT_EQ(run("first", {}), 0);
  EXPECT_TRUE(fs::exists(dir / "runs" / "first" / "cloud.ply"));
  const fs::path cache = dir / "runs" / ".omnirig-cache" / "rectification";
  const std::vector<fs::path> tables = TablesFiles(cache);
  ASSERT_EQ(tables.size(), 1u);
  const ino_t written = Inode(tables[0]);
  // A later run into a sibling folder reads the file (building would write a new one over it).
  ASSERT_EQ(run("second", {}), 0);
  EXPECT_EQ(TablesFiles(cache), tables);
  EXPECT_EQ(Inode(tables[0]), written);
  // --cache-dir names the folder; "none" keeps nothing on disk.
  ASSERT_EQ(run("third", {"--cache-dir", (dir / "elsewhere").string()}), 0);
  EXPECT_EQ(TablesFiles(dir / "elsewhere" / "rectification").size(), 1u);
  ASSERT_EQ(run("fourth", {"--cache-dir", "none"}), 0);
  EXPECT_TRUE(fs::exists(dir / "runs" / "fourth" / "cloud.ply"));
  EXPECT_EQ(TablesFiles(cache).size(), 1u);
  EXPECT_FALSE(fs::exists(dir / "runs" / "none"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace omnirig::cli
