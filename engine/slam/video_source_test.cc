// The video frame source: tiny videos written with cv::VideoWriter (FFV1 in Matroska, lossless,
// so each frame's grey level tells which frame was decoded; mp4v in MP4 for the lossy path).

#include "engine/slam/video_source.h"

#include <unistd.h>

#include <fstream>

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

namespace fs = std::filesystem;

class VideoSource : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("omnirig_video_source_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A video of `frames` frames of 64 x `height` whose grey level is base + 8 * i (a stacked
  // video: the bottom half 4 levels higher).
  fs::path Write(const std::string& name, int frames, double fps, int base, int height = 48,
                 bool stacked = false) {
    const fs::path path = dir_ / name;
    const bool mkv = path.extension() == ".mkv";
    const int fourcc = mkv ? cv::VideoWriter::fourcc('F', 'F', 'V', '1')
                           : cv::VideoWriter::fourcc('m', 'p', '4', 'v');
    cv::VideoWriter writer(path.string(), cv::CAP_FFMPEG, fourcc, fps, cv::Size(64, height));
    EXPECT_TRUE(writer.isOpened()) << name;
    for (int i = 0; i < frames; ++i) {
      cv::Mat frame(height, 64, CV_8UC3, cv::Scalar::all(base + 8 * i));
      if (stacked) frame.rowRange(height / 2, height).setTo(cv::Scalar::all(base + 8 * i + 4));
      writer.write(frame);
    }
    return path;
  }

  static double Grey(const cv::Mat& image) { return cv::mean(image)[0]; }

  fs::path dir_;
};

TEST(PairTimestamps, PairsWithinTheToleranceAndNamesFramesThatDoNot) {
  const std::vector<double> a = {0.0, 0.1, 0.2, 0.3};
  const std::vector<double> b = {0.004, 0.101, 0.198, 0.3};
  const auto pairs = PairTimestamps(a, b, 0.005);
  ASSERT_EQ(pairs.size(), 4u);
  EXPECT_EQ(pairs[2].first, 2);
  EXPECT_EQ(pairs[2].second, 2);
  // cam1 dropped its frame at 0.2 s: cam0's frame 2 has no partner.
  try {
    PairTimestamps(a, {0.0, 0.1, 0.3}, 0.005);
    FAIL() << "a dropped frame was paired";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("cam0 frame 2 at 0.2 s"), std::string::npos) << e.what();
  }
  // A constant offset beyond the tolerance pairs nothing.
  EXPECT_THROW(PairTimestamps(a, {0.02, 0.12, 0.22, 0.32}, 0.005), InvalidArgument);
  EXPECT_EQ(PairTimestamps(a, {0.02, 0.12, 0.22, 0.32}, 0.025).size(), 4u);
}

TEST_F(VideoSource, PairsTwoVideosByTimestampAndDecodesTheRightFrames) {
  StereoVideoFiles files{Write("cam0.mkv", 12, 10.0, 20), Write("cam1.mkv", 12, 10.0, 24)};
  const StereoVideoInfo info = ProbeStereoVideo(files);
  EXPECT_EQ(info.video[0].frame_count, 12);
  EXPECT_DOUBLE_EQ(info.video[0].fps, 10.0);
  EXPECT_EQ(info.width[1], 64);
  EXPECT_EQ(info.height[1], 48);
  EXPECT_EQ(info.video[0].codec, "FFV1");

  const std::vector<StereoVideoFrame> frames = PairStereoVideoFrames(files, {});
  ASSERT_EQ(frames.size(), 12u);
  EXPECT_EQ(frames[0].name, "t000000.000");
  EXPECT_EQ(frames[11].name, "t000001.100");
  EXPECT_NEAR(frames[7].timestamp_s, 0.7, 1e-9);
  StereoVideoReader reader(files, frames);
  for (int k : {0, 1, 5, 11, 3}) {  // forward with gaps, then back (reopens)
    const StereoImages images = reader.Load(k);
    EXPECT_NEAR(Grey(images.cam0), 20 + 8 * k, 1.0) << k;
    EXPECT_NEAR(Grey(images.cam1), 24 + 8 * k, 1.0) << k;
    EXPECT_EQ(images.cam0.type(), CV_8UC3);
  }
}

TEST_F(VideoSource, FrameStepAndTimeRangeSelectFrames) {
  StereoVideoFiles files{Write("cam0.mp4", 12, 10.0, 20), Write("cam1.mp4", 12, 10.0, 24)};
  VideoFrameOptions options;
  options.frame_step = 3;
  std::vector<StereoVideoFrame> frames = PairStereoVideoFrames(files, options);
  ASSERT_EQ(frames.size(), 4u);
  EXPECT_EQ(frames[1].index[0], 3);
  EXPECT_EQ(frames[3].name, "t000000.900");

  options.frame_step = 2;
  options.start_s = 0.25;
  options.end_s = 0.75;  // 0.3 .. 0.7: five frames, every second one
  frames = PairStereoVideoFrames(files, options);
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_EQ(frames[0].index[0], 3);
  EXPECT_EQ(frames[2].index[1], 7);
  StereoVideoReader reader(files, frames);
  EXPECT_NEAR(Grey(reader.Load(2).cam0), 20 + 8 * 7, 4.0);  // mp4v is lossy

  options.start_s = 5.0;
  options.end_s = 6.0;
  EXPECT_THROW(PairStereoVideoFrames(files, options), InvalidArgument);
  options.end_s = 4.0;  // before start_s
  EXPECT_THROW(options.Check(), InvalidArgument);
}

TEST_F(VideoSource, StackedVideoSplitsTopAndBottom) {
  const StereoVideoFiles files{Write("stacked.mkv", 5, 10.0, 30, 96, true), ""};
  const StereoVideoInfo info = ProbeStereoVideo(files);
  EXPECT_EQ(info.height[0], 48);
  EXPECT_EQ(info.height[1], 48);
  const auto frames = PairStereoVideoFrames(files, {});
  ASSERT_EQ(frames.size(), 5u);
  StereoVideoReader reader(files, frames);
  const StereoImages images = reader.Load(4);
  EXPECT_EQ(images.cam0.rows, 48);
  EXPECT_NEAR(Grey(images.cam0), 30 + 32, 1.0);
  EXPECT_NEAR(Grey(images.cam1), 30 + 32 + 4, 1.0);
}

// What each refusal says: the reason, with the file names, before any frame is processed.
TEST_F(VideoSource, RefusesVideosThatCannotBePaired) {
  const fs::path cam0 = Write("cam0.mkv", 12, 10.0, 20);
  const auto message = [](const StereoVideoFiles& files) {
    try {
      ProbeStereoVideo(files);
    } catch (const InvalidArgument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(
      message({cam0, Write("short.mkv", 8, 10.0, 20)}).find("different frame counts (12 and 8)"),
      std::string::npos);
  EXPECT_NE(message({cam0, Write("fast.mkv", 12, 20.0, 20)}).find("different frame rates"),
            std::string::npos);
  std::ofstream(dir_ / "garbage.mp4") << "this is not a video at all";
  EXPECT_NE(message({cam0, dir_ / "garbage.mp4"}).find("garbage.mp4 cannot be opened as a video"),
            std::string::npos);
}

}  // namespace
}  // namespace omnirig::slam
