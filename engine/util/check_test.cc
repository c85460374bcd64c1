#include "engine/util/check.h"

#include <gtest/gtest.h>

#include <string>

namespace omnirig {
namespace {

TEST(Check, PassingCheckDoesNotThrow) { EXPECT_NO_THROW(OMNIRIG_CHECK(1 + 1 == 2, "arithmetic")); }

TEST(Check, FailingCheckThrowsWithMessageAndShortLocation) {
  const int value = 7;
  try {
    OMNIRIG_CHECK(value < 5, "value must be below 5, got " << value);
    FAIL() << "no exception";
  } catch (const InvalidArgument& e) {
    const std::string message = e.what();
    // The location is module/file only: the build machine's directories never reach a user.
    EXPECT_EQ(message.rfind("value must be below 5, got 7 (util/check_test.cc:", 0), 0u) << message;
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
