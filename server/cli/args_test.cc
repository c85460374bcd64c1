#include "server/cli/args.h"

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig::cli {
namespace {

ArgParser MakeParser() {
  ArgParser parser("calibrate", "test");
  parser.AddOption("o", "calib.json", "output");
  parser.AddOption("cols", "8", "columns");
  parser.AddFlag("verbose", "talk");
  parser.SetPositional("IMAGES...", "images");
  return parser;
}

TEST(ArgParser, LongShortInlineAndPositional) {
  ArgParser parser = MakeParser();
  ASSERT_TRUE(parser.Parse({"a.png", "-o", "out.json", "--cols=9", "--verbose", "b.png"}));
  EXPECT_EQ(parser.Get("o"), "out.json");
  EXPECT_EQ(parser.GetInt("cols"), 9);
  EXPECT_TRUE(parser.Has("verbose"));
  EXPECT_EQ(parser.positional(), (std::vector<std::string>{"a.png", "b.png"}));
  EXPECT_NE(parser.Help().find("  -o VALUE"), std::string::npos);
  EXPECT_NE(parser.Help().find("  --cols VALUE"), std::string::npos);
}

TEST(ArgParser, DefaultsAndErrors) {
  ArgParser defaults = MakeParser();
  ASSERT_TRUE(defaults.Parse({}));
  EXPECT_EQ(defaults.Get("o"), "calib.json");
  EXPECT_FALSE(defaults.Has("verbose"));

  ArgParser unknown = MakeParser();
  EXPECT_FALSE(unknown.Parse({"--nope", "1"}));
  EXPECT_EQ(unknown.exit_code(), 2);

  ArgParser missing_value = MakeParser();
  EXPECT_FALSE(missing_value.Parse({"--cols"}));
  EXPECT_EQ(missing_value.exit_code(), 2);

  ArgParser bad_number = MakeParser();
  ASSERT_TRUE(bad_number.Parse({"--cols", "eight"}));
  EXPECT_THROW(bad_number.GetInt("cols"), InvalidArgument);

  ArgParser help = MakeParser();
  testing::internal::CaptureStdout();
  EXPECT_FALSE(help.Parse({"--help"}));
  EXPECT_EQ(help.exit_code(), 0);
  EXPECT_NE(testing::internal::GetCapturedStdout().find("usage: omnirig calibrate"),
            std::string::npos);
}

}  // namespace
}  // namespace omnirig::cli
