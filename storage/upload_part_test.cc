// A resumable upload's part: what the server reports of it, the lock that keeps two requests
// from writing it at once, starting over, and publishing it whole.

#include "storage/upload_part.h"

#include <unistd.h>

#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

namespace omnirig::storage {
namespace {

namespace fs = std::filesystem;

class UploadPartTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("omnirig_upload_part_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path uploads() const { return dir_ / "uploads"; }
  fs::path dir_;
};

TEST_F(UploadPartTest, ReportsLocksAndPublishes) {
  EXPECT_FALSE(FindUploadPart(uploads(), "cam0/a.mp4").total_bytes);
  {
    UploadPartWriter part(uploads(), "cam0/a.mp4", 10);
    part.Append("abcd", 4);
    part.Sync();
    EXPECT_EQ(part.size(), 4);
    // A second request on the same part is refused while the first holds it.
    EXPECT_THROW(UploadPartWriter(uploads(), "cam0/a.mp4", 10), UploadBusy);
  }
  UploadPartStatus status = FindUploadPart(uploads(), "cam0/a.mp4");
  EXPECT_EQ(status.received_bytes, 4);
  EXPECT_EQ(status.total_bytes, 10);

  UploadPartWriter part(uploads(), "cam0/a.mp4", 10);
  EXPECT_EQ(part.size(), 4);  // resumes where the part ends
  part.Append("efghij", 6);
  const fs::path final_path = dir_ / "images" / "cam0" / "a.mp4";
  part.Publish(final_path);
  std::ifstream in(final_path);
  std::stringstream content;
  content << in.rdbuf();
  EXPECT_EQ(content.str(), "abcdefghij");
  EXPECT_FALSE(FindUploadPart(uploads(), "cam0/a.mp4").total_bytes);
}

TEST_F(UploadPartTest, StartsOverAndRemoves) {
  {
    UploadPartWriter part(uploads(), "b.mkv", 100);
    part.Append("0123456789", 10);
  }
  {
    UploadPartWriter other(uploads(), "b.mkv", 50);  // the same name, another file
    other.Append("xy", 2);
  }
  EXPECT_EQ(FindUploadPart(uploads(), "b.mkv").received_bytes, 10);  // the larger part
  EXPECT_EQ(RemoveUploadParts(uploads(), "b.mkv", 100), 1);          // all but total 100
  UploadPartWriter part(uploads(), "b.mkv", 100);
  part.Truncate();
  EXPECT_EQ(part.size(), 0);
  part.Append("z", 1);
  part.Remove();
  EXPECT_FALSE(FindUploadPart(uploads(), "b.mkv").total_bytes);
  // A writer that created a part and wrote nothing leaves nothing behind.
  { UploadPartWriter empty(uploads(), "c.avi", 5); }
  EXPECT_FALSE(FindUploadPart(uploads(), "c.avi").total_bytes);
}

}  // namespace
}  // namespace omnirig::storage
