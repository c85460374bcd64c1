#include "server/content_range.h"

#include <gtest/gtest.h>

#include "server/http.h"

namespace omnirig::server {
namespace {

TEST(ContentRange, ParsesFirstLastTotal) {
  const ContentRange range = ParseContentRange("bytes 1048576-2097151/5242880");
  EXPECT_EQ(range.first, 1048576);
  EXPECT_EQ(range.last, 2097151);
  EXPECT_EQ(range.total, 5242880);
  EXPECT_EQ(range.length(), 1048576);
}

TEST(ContentRange, RefusesMalformedAndInconsistentRanges) {
  for (const char* text : {"", "bytes", "bytes */100", "bytes 0-9", "bytes 5-4/10", "bytes 0-10/10",
                           "bytes -1-4/10", "bytes 0-4/10 ", "items 0-4/10"}) {
    try {
      ParseContentRange(text);
      ADD_FAILURE() << "accepted '" << text << "'";
    } catch (const HttpError& e) {
      EXPECT_EQ(e.status, 400) << text;
      EXPECT_NE(std::string(e.what()).find("Content-Range"), std::string::npos);
    }
  }
}

}  // namespace
}  // namespace omnirig::server
