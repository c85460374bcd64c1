#include "engine/slam/image_source.h"

#include <unistd.h>

#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

namespace fs = std::filesystem;

class ImageSource : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("omnirig_image_source_" + std::to_string(::getpid()));
    fs::create_directories(dir_ / "cam0");
    fs::create_directories(dir_ / "cam1");
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A 32x24 image of grey level `level`.
  void Write(const std::string& name, int level) {
    ASSERT_TRUE(
        cv::imwrite((dir_ / name).string(), cv::Mat(24, 32, CV_8UC3, cv::Scalar::all(level))));
  }

  fs::path dir_;
};

TEST_F(ImageSource, LoadsEachPairsTwoImagesInColour) {
  Write("cam0/a.png", 10);
  Write("cam1/a.png", 20);
  Write("cam0/b.png", 30);
  Write("cam1/b.png", 40);
  const StereoFrameLoader load = StereoImageLoader(
      dir_, MatchImagePairs({"cam0/a.png", "cam1/a.png", "cam0/b.png", "cam1/b.png"}));
  const StereoImages second = load(1);
  ASSERT_EQ(second.cam0.type(), CV_8UC3);
  EXPECT_EQ(second.cam0.at<cv::Vec3b>(0, 0)[0], 30);
  EXPECT_EQ(second.cam1.at<cv::Vec3b>(5, 7)[2], 40);
  EXPECT_EQ(load(0).cam1.at<cv::Vec3b>(0, 0)[1], 20);
}

TEST_F(ImageSource, AnUnreadableImageIsNamed) {
  Write("cam0/a.png", 10);
  std::ofstream(dir_ / "cam1/a.png") << "not a png";
  const StereoFrameLoader load =
      StereoImageLoader(dir_, MatchImagePairs({"cam0/a.png", "cam1/a.png"}));
  try {
    load(0);
    FAIL() << "no exception";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("cam1/a.png cannot be read"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace omnirig::slam
