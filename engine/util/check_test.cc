#include "engine/util/check.h"

#include <gtest/gtest.h>

#include <string>

namespace omnirig {
namespace {

TEST(Check, PassingCheckDoesNotThrow) { EXPECT_NO_THROW(OMNIRIG_CHECK(1 + 1 == 2, "arithmetic")); }

TEST(Check, FailingCheckThrowsTheMessageAndKeepsTheLocationApart) {
  const int value = 7;
  try {
    OMNIRIG_CHECK(value < 5, "value must be below 5, got " << value);
    FAIL() << "no exception";
  } catch (const InvalidArgument& e) {
    // The message reaches API users: no source location in it. The location (module/file
    // only, free of the build machine's directories) is for the log.
    EXPECT_STREQ(e.what(), "value must be below 5, got 7");
    EXPECT_EQ(e.where().rfind("util/check_test.cc:", 0), 0u) << e.where();
  }
}

TEST(Check, ShortSourcePathKeepsTheLastTwoComponents) {
  EXPECT_STREQ(internal::ShortSourcePath("/a/b/engine/calib/pipeline.cc"), "calib/pipeline.cc");
  EXPECT_STREQ(internal::ShortSourcePath("calib/pipeline.cc"), "calib/pipeline.cc");
  EXPECT_STREQ(internal::ShortSourcePath("pipeline.cc"), "pipeline.cc");
  EXPECT_STREQ(internal::ShortSourcePath(""), "");
}

}  // namespace
}  // namespace omnirig
