#include "engine/features/features.h"

#include <gtest/gtest.h>

#include "engine/util/check.h"
#include <opencv2/imgproc.hpp>

namespace omnirig {
namespace {

CameraModel Camera() {
  CameraModel camera;
  camera.width = 640;
  camera.height = 480;
  camera.intrinsics.params = {0.9, 150, 150, 322, 238, 0, 0, 0, 0, 0, 0};
  return camera;
}

// A mirror annulus (rim 220 px, hole 50 px) filled with random blobs, dark elsewhere.
cv::Mat MirrorImage(const CameraModel& camera) {
  cv::Mat image(camera.height, camera.width, CV_8UC3, cv::Scalar::all(6));
  // Blobs of many sizes and grey levels on mid grey: plenty of scale-space extrema.
  cv::Mat texture(camera.height, camera.width, CV_8UC3, cv::Scalar::all(128));
  cv::RNG rng(3);
  for (int i = 0; i < 1500; ++i) {
    cv::circle(texture, cv::Point(rng.uniform(0, camera.width), rng.uniform(0, camera.height)),
               rng.uniform(2, 9), cv::Scalar::all(rng.uniform(30, 250)), cv::FILLED);
  }
  cv::Mat mask(camera.height, camera.width, CV_8U, cv::Scalar(0));
  const cv::Point centre(322, 238);
  cv::circle(mask, centre, 220, cv::Scalar(255), cv::FILLED);
  cv::circle(mask, centre, 50, cv::Scalar(0), cv::FILLED);
  texture.copyTo(image, mask);
  return image;
}

TEST(DetectFeatures, StaysInsideTheMaskAndLiftsEveryKeypoint) {
  const CameraModel camera = Camera();
  const cv::Mat image = MirrorImage(camera);
  FeatureOptions options;
  const cv::Mat mask = MirrorMask(image, PrincipalPoint(camera), options.mirror_mask);
  options.max_features = 500;
  const CameraFeatures features = DetectFeatures(camera, image, mask, options);
  ASSERT_GT(features.size(), 100);
  EXPECT_EQ(features.descriptors.rows, features.size());
  for (int i = 0; i < features.size(); ++i) {
    const double r = (features.pixels[i] - Eigen::Vector2d(322, 238)).norm();
    EXPECT_GT(r, 50 + 8 - 2);  // half-resolution detection: about a pixel of slack
    EXPECT_LT(r, 220 - 8 + 2);
    EXPECT_NEAR(features.bearings[i].norm(), 1.0, 1e-12);
    const auto pixel = Project(camera.intrinsics, features.bearings[i]);
    ASSERT_TRUE(pixel.has_value());
    EXPECT_LT((*pixel - features.pixels[i]).norm(), 1e-6);
  }
  EXPECT_LT(MeanIntensity(cv::Mat(480, 640, CV_8UC3, cv::Scalar::all(0)), mask), 1.0);
}

// A keypoint detector without position bias finds the features of an image turned by 180
// degrees at the turned positions. OpenCV's SIFT alone puts every keypoint 0.25 px of its input
// right and down, so the turned detections would sit 2 x 0.5 = 1 full-size pixel off here.
TEST(DetectFeatures, HasNoPositionBias) {
  const CameraModel camera = Camera();
  cv::Mat image(camera.height, camera.width, CV_8UC3, cv::Scalar::all(128));
  cv::RNG rng(5);
  for (int i = 0; i < 1500; ++i) {
    cv::circle(image, cv::Point(rng.uniform(0, camera.width), rng.uniform(0, camera.height)),
               rng.uniform(2, 9), cv::Scalar::all(rng.uniform(30, 250)), cv::FILLED, cv::LINE_AA);
  }
  cv::GaussianBlur(image, image, cv::Size(0, 0), 1.0);
  cv::Mat turned;
  cv::rotate(image, turned, cv::ROTATE_180);
  FeatureOptions options;
  options.max_features = 1000;
  const CameraFeatures a = DetectFeatures(camera, image, cv::Mat(), options);
  const CameraFeatures b = DetectFeatures(camera, turned, cv::Mat(), options);
  const Eigen::Vector2d corner(camera.width - 1, camera.height - 1);
  std::vector<double> dx, dy;
  for (const Eigen::Vector2d& p : a.pixels) {
    const Eigen::Vector2d expected = corner - p;  // where the turned image shows it
    double best = 1.5;
    Eigen::Vector2d offset;
    for (const Eigen::Vector2d& q : b.pixels) {
      if ((q - expected).norm() < best) {
        best = (q - expected).norm();
        offset = q - expected;
      }
    }
    if (best >= 1.5) continue;
    dx.push_back(offset.x());
    dy.push_back(offset.y());
  }
  ASSERT_GT(dx.size(), 200u);
  std::nth_element(dx.begin(), dx.begin() + dx.size() / 2, dx.end());
  std::nth_element(dy.begin(), dy.begin() + dy.size() / 2, dy.end());
  EXPECT_LT(std::abs(dx[dx.size() / 2]), 0.15);
  EXPECT_LT(std::abs(dy[dy.size() / 2]), 0.15);
}

TEST(FeatureOptions, RejectsNonsense) {
  FeatureOptions options;
  options.detection_scale = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace omnirig
