#include "engine/util/image_pairs.h"

#include <string>

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig {
namespace {

// The message of the InvalidArgument that `f` throws ("" when it does not throw).
template <typename F>
std::string ErrorOf(F f) {
  try {
    f();
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "";
}

TEST(ImagePairs, PairsMatchByNameAndMissingPartnersAreRefused) {
  const auto pairs = MatchImagePairs(
      {"cam0/b.png", "cam1/a.png", "cam0/a.png", "cam1/b.png", "notes.txt", "cam2/a.png"});
  ASSERT_EQ(pairs.size(), 2u);
  EXPECT_EQ(pairs[0].name, "a.png");
  EXPECT_EQ(pairs[0].cam0, "cam0/a.png");
  EXPECT_EQ(pairs[0].cam1, "cam1/a.png");
  const std::string missing = ErrorOf([] {
    MatchImagePairs({"cam0/a.png", "cam1/a.png", "cam0/c.png", "cam1/d.png"});
  });
  EXPECT_NE(missing.find("cam0/c.png has no cam1/c.png"), std::string::npos) << missing;
  EXPECT_NE(missing.find("cam1/d.png has no cam0/d.png"), std::string::npos) << missing;
  EXPECT_NE(ErrorOf([] {
              MatchImagePairs({"cam0/a.png", "left/a.png"});
            }).find("cam1/"),
            std::string::npos);
}

TEST(ImagePairs, NamesReadAsTimestampsWhenTheyAreNumbers) {
  ASSERT_TRUE(NameAsTimestamp("1403636579.763.png").has_value());
  EXPECT_DOUBLE_EQ(*NameAsTimestamp("1403636579.763.png"), 1403636579.763);
  EXPECT_FALSE(NameAsTimestamp("frame_001.png").has_value());
  EXPECT_FALSE(NameAsTimestamp(".png").has_value());
  // A recording's frames: "t" and the time.
  ASSERT_TRUE(NameAsTimestamp("t000012.345.png").has_value());
  EXPECT_DOUBLE_EQ(*NameAsTimestamp("t000012.345.png"), 12.345);
  EXPECT_FALSE(NameAsTimestamp("t.png").has_value());
  EXPECT_FALSE(NameAsTimestamp("top.png").has_value());
}

}  // namespace
}  // namespace omnirig
