// The CLI's cache folder (--cache-dir): next to the outputs by default, as given, or none.

#include "server/cli/job_options.h"

#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "server/cli/args.h"

namespace omnirig::cli {
namespace {

namespace fs = std::filesystem;

fs::path CacheDir(const std::vector<std::string>& argv, const fs::path& out_dir) {
  ArgParser parser("stereo", "test");
  AddCacheDirOption(&parser);
  EXPECT_TRUE(parser.Parse(argv));
  return CacheDirFromArgs(parser, out_dir);
}

TEST(CliCacheDir, NextToTheOutputsByDefaultAsGivenOrNone) {
  // Runs into sibling output folders share one cache.
  EXPECT_EQ(CacheDir({}, "/data/runs/out1"), fs::path("/data/runs/.omnirig-cache"));
  EXPECT_EQ(CacheDir({}, "/data/runs/out2/"), fs::path("/data/runs/.omnirig-cache"));
  EXPECT_EQ(CacheDir({}, "/data/runs/x/../out3"), fs::path("/data/runs/.omnirig-cache"));
  EXPECT_EQ(CacheDir({}, "out"), fs::current_path() / ".omnirig-cache");
  EXPECT_EQ(CacheDir({"--cache-dir", "/var/cache/omnirig"}, "/data/out"),
            fs::path("/var/cache/omnirig"));
  EXPECT_TRUE(CacheDir({"--cache-dir", "none"}, "/data/out").empty());
}

}  // namespace
}  // namespace omnirig::cli
