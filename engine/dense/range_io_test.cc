#include "engine/dense/range_io.h"

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

namespace omnirig::dense {
namespace {

class RangeIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("omnirig_range_io_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

// A panorama whose range grows from 0.5 m (left) to 8 m (right), with an unknown band.
cv::Mat RampPanorama() {
  cv::Mat range(120, 400, CV_32F);
  for (int r = 0; r < range.rows; ++r) {
    for (int c = 0; c < range.cols; ++c) {
      range.at<float>(r, c) = r >= 50 && r < 60 ? 0.f : 0.5f * std::pow(16.f, c / 399.f);
    }
  }
  return range;
}

TEST_F(RangeIoTest, ThePngReadsBackAsThePreview) {
  const cv::Mat range = RampPanorama();
  const std::filesystem::path path = dir_ / "a_range.png";
  WriteRangePng(path, range);
  const cv::Mat read = cv::imread(path.string(), cv::IMREAD_COLOR);
  const cv::Mat preview = RangePreview(range);
  ASSERT_EQ(read.size(), range.size());
  ASSERT_EQ(read.type(), CV_8UC3);
  EXPECT_EQ(cv::norm(read, preview, cv::NORM_INF), 0.0);
  // Unknown cells are black; near is red, far is blue.
  EXPECT_EQ(read.at<cv::Vec3b>(55, 200), cv::Vec3b(0, 0, 0));
  const cv::Vec3b near = read.at<cv::Vec3b>(0, 0), far = read.at<cv::Vec3b>(0, 399);
  EXPECT_GT(near[2], near[0]);
  EXPECT_GT(far[0], far[2]);
  // Colours change monotonically along the ramp: no two distant columns share a colour.
  EXPECT_NE(read.at<cv::Vec3b>(0, 100), read.at<cv::Vec3b>(0, 300));
}

TEST_F(RangeIoTest, APanoramaWithNothingKnownIsBlack) {
  const cv::Mat range = cv::Mat::zeros(30, 60, CV_32F);
  WriteRangePng(dir_ / "empty_range.png", range);
  const cv::Mat read = cv::imread((dir_ / "empty_range.png").string(), cv::IMREAD_COLOR);
  ASSERT_EQ(read.size(), range.size());
  EXPECT_EQ(cv::countNonZero(read.reshape(1)), 0);
}

TEST_F(RangeIoTest, AnUnwritablePathNamesTheFile) {
  const std::filesystem::path path = dir_ / "a_range.png";
  std::filesystem::create_directories(path);  // a directory where the file should go
  try {
    WriteRangePng(path, RampPanorama());
    FAIL() << "expected std::runtime_error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("a_range.png"), std::string::npos) << e.what();
  }
}

TEST_F(RangeIoTest, TheTiffKeepsTheRangesExactly) {
  const cv::Mat range = RampPanorama();
  WriteRangeTiff(dir_ / "a_range.tiff", range);
  const cv::Mat read = cv::imread((dir_ / "a_range.tiff").string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(read.type(), CV_32FC1);
  EXPECT_EQ(cv::norm(read, range, cv::NORM_INF), 0.0);
}

}  // namespace
}  // namespace omnirig::dense
