#include "storage/names.h"

#include <gtest/gtest.h>

#include <stdexcept>

namespace omnirig::storage {
namespace {

TEST(Names, AcceptsPlainNamesAndOneFolder) {
  EXPECT_EQ(CheckSafeName("000012.png"), "000012.png");
  EXPECT_EQ(CheckSafeName("cam0/000012.png"), "cam0/000012.png");
  EXPECT_EQ(CheckSafeName("left_1-a+b.JPG"), "left_1-a+b.JPG");
}

TEST(Names, RefusesUnsafeNames) {
  for (const std::string bad :
       {"", "/etc/passwd", "../a.png", "cam0/../../a.png", "a/b/c.png", ".hidden.png",
        "cam0/.x.png", "a\\b.png", "a b.png", "cam0//a.png", "cam0/", "..", ".", "a\nb"}) {
    EXPECT_THROW(CheckSafeName(bad), std::invalid_argument) << "'" << bad << "'";
  }
  EXPECT_THROW(CheckSafeName(std::string(kMaxNameLength + 1, 'a')), std::invalid_argument);
  EXPECT_THROW(CheckSafeName("cam0/a.png", 1), std::invalid_argument);
}

}  // namespace
}  // namespace omnirig::storage
