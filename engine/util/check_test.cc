#include "engine/util/check.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include "engine/util/option_check.h"

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

std::string OptionCheckMessage(const std::function<void()>& check) {
  try {
    check();
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "";
}

TEST(OptionCheck, IntervalEndsAreOpenOrClosedAsWritten) {
  for (const double x : {1e-9, 0.5, 45.0}) {
    EXPECT_NO_THROW(OMNIRIG_CHECK_IN(x, '(', 0, 45, ']')) << x;
  }
  for (const double x : {0.0, 45.5})
    EXPECT_THROW(OMNIRIG_CHECK_IN(x, '(', 0, 45, ']'), InvalidArgument);
  const int count = 1;
  EXPECT_NO_THROW(OMNIRIG_CHECK_IN(count, '[', 1, 16, ')'));
  const int top = 16;
  EXPECT_THROW(OMNIRIG_CHECK_IN(top, '[', 1, 16, ')'), InvalidArgument);
}

TEST(OptionCheck, MessagesNameTheFieldTheRangeAndTheValue) {
  const double max_parallax_deg = 50;
  EXPECT_EQ(OptionCheckMessage([&] { OMNIRIG_CHECK_IN(max_parallax_deg, '(', 0, 45, ']'); }),
            "max_parallax_deg must lie in (0, 45], got 50");
  const double huber_px = 0;
  EXPECT_EQ(OptionCheckMessage([&] { OMNIRIG_CHECK_POSITIVE(huber_px); }),
            "huber_px must be positive, got 0");
  const int margin = -2;
  EXPECT_EQ(OptionCheckMessage([&] { OMNIRIG_CHECK_NON_NEGATIVE(margin); }),
            "margin must not be negative, got -2");
  const int min_inliers = 7;
  EXPECT_EQ(OptionCheckMessage([&] { OMNIRIG_CHECK_AT_LEAST(min_inliers, 8); }),
            "min_inliers must be at least 8, got 7");
  EXPECT_EQ(OptionCheckMessage([&] { OMNIRIG_CHECK_AT_LEAST(min_inliers, 7); }), "");
}

TEST(OptionCheck, FloatingPointOptionsMustBeFinite) {
  for (const double x : {std::numeric_limits<double>::infinity(), std::nan("")}) {
    EXPECT_THROW(OMNIRIG_CHECK_POSITIVE(x), InvalidArgument);
    EXPECT_THROW(OMNIRIG_CHECK_NON_NEGATIVE(x), InvalidArgument);
    EXPECT_THROW(OMNIRIG_CHECK_AT_LEAST(x, 1), InvalidArgument);
    EXPECT_THROW(OMNIRIG_CHECK_IN(x, '[', 0, 1, ']'), InvalidArgument);
  }
}

}  // namespace
}  // namespace omnirig
