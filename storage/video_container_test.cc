// The container checks on hand-made files: whole, cut short, and missing their index.

#include "storage/video_container.h"

#include <unistd.h>

#include <fstream>

#include <gtest/gtest.h>

namespace omnirig::storage {
namespace {

namespace fs = std::filesystem;
using Status = VideoContainer::Status;

std::string Be32(uint32_t v) {
  return {static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8),
          static_cast<char>(v)};
}
std::string Le32(uint32_t v) {
  return {static_cast<char>(v), static_cast<char>(v >> 8), static_cast<char>(v >> 16),
          static_cast<char>(v >> 24)};
}
std::string Box(const std::string& type, size_t payload) {
  return Be32(static_cast<uint32_t>(8 + payload)) + type + std::string(payload, 'x');
}

class VideoContainerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = fs::temp_directory_path() / ("omnirig_video_container_" + std::to_string(::getpid()));
  }
  void TearDown() override { fs::remove(path_); }
  VideoContainer Check(const std::string& bytes) {
    std::ofstream(path_, std::ios::binary) << bytes;
    return CheckVideoContainer(path_);
  }
  fs::path path_;
};

TEST(IsVideoName, ByExtension) {
  EXPECT_TRUE(IsVideoName("cam0.mp4"));
  EXPECT_TRUE(IsVideoName("run/STACKED.MKV"));
  EXPECT_TRUE(IsVideoName("a.avi"));
  EXPECT_FALSE(IsVideoName("cam0/0001.png"));
  EXPECT_FALSE(IsVideoName("mp4"));
}

TEST_F(VideoContainerTest, Mp4BoxesMustTileTheFileAndHoldAnIndex) {
  const std::string ftyp = Be32(20) + "ftypisom" + std::string(8, '\0');
  const std::string whole = ftyp + Box("free", 0) + Box("mdat", 100) + Box("moov", 40);
  VideoContainer result = Check(whole);
  EXPECT_EQ(result.status, Status::kOk) << result.problem;
  EXPECT_EQ(result.content_type, "video/mp4");

  result = Check(whole.substr(0, whole.size() - 5));
  EXPECT_EQ(result.status, Status::kCorrupt);
  EXPECT_NE(result.problem.find("box 'moov'"), std::string::npos) << result.problem;
  EXPECT_NE(result.problem.find("incomplete"), std::string::npos);

  // A recorder killed before it wrote the index: mdat only.
  result = Check(ftyp + Box("mdat", 100));
  EXPECT_EQ(result.status, Status::kCorrupt);
  EXPECT_NE(result.problem.find("no 'moov' box"), std::string::npos);

  // 64-bit sizes and a last box running to the end (size 0).
  const std::string large = Be32(1) + "mdat" + Be32(0) + Be32(16 + 30) + std::string(30, 'y');
  EXPECT_EQ(Check(ftyp + large + Be32(0) + "moov" + "zz").status, Status::kOk);
  // A QuickTime file names its brand.
  EXPECT_EQ(Check(Be32(20) + "ftypqt  " + std::string(8, '\0') + Box("moov", 4)).format,
            "quicktime");
}

TEST_F(VideoContainerTest, MatroskaSegmentSizeMustFit) {
  const std::string ebml = "\x1A\x45\xDF\xA3" + std::string("\x84") + "abcd";
  const std::string segment_id = "\x18\x53\x80\x67";
  const std::string size_40 = std::string("\x01\x00\x00\x00\x00\x00\x00", 7) + "\x28";
  const std::string whole = ebml + segment_id + size_40 + std::string(40, 's');
  VideoContainer result = Check(whole);
  EXPECT_EQ(result.status, Status::kOk) << result.problem;
  EXPECT_EQ(result.content_type, "video/x-matroska");
  result = Check(whole.substr(0, whole.size() - 1));
  EXPECT_EQ(result.status, Status::kCorrupt);
  EXPECT_NE(result.problem.find("incomplete"), std::string::npos) << result.problem;
  // A live recording's segment of unknown size cannot be checked further: accepted.
  const std::string unknown = std::string("\x01\xFF\xFF\xFF\xFF\xFF\xFF\xFF", 8);
  EXPECT_EQ(Check(ebml + segment_id + unknown + "data").status, Status::kOk);
  EXPECT_EQ(Check(ebml + "\x1F\x43\xB6\x75" + size_40 + std::string(40, 's')).status,
            Status::kCorrupt);
}

TEST_F(VideoContainerTest, AviRiffSizesMustTileTheFile) {
  const std::string riff = "RIFF" + Le32(4 + 20) + "AVI " + std::string(20, 'a');
  EXPECT_EQ(Check(riff).status, Status::kOk);
  const std::string avix = "RIFF" + Le32(4 + 10) + "AVIX" + std::string(10, 'b');
  EXPECT_EQ(Check(riff + avix).status, Status::kOk);
  const VideoContainer cut = Check(riff + avix.substr(0, 16));
  EXPECT_EQ(cut.status, Status::kCorrupt);
  EXPECT_NE(cut.problem.find("incomplete"), std::string::npos) << cut.problem;
}

TEST_F(VideoContainerTest, OtherFilesAreNotVideos) {
  EXPECT_EQ(Check("\x89PNG\r\n\x1a\n0000000000000000").status, Status::kNotAVideo);
  EXPECT_EQ(Check("short").status, Status::kNotAVideo);
}

}  // namespace
}  // namespace omnirig::storage
