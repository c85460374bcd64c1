#include "engine/calib/model_io.h"

#include <gtest/gtest.h>
#include <opencv2/ccalib/omnidir.hpp>

namespace omnirig {
namespace {

CameraModel Camera() {
  CameraModel camera;
  camera.width = 1280;
  camera.height = 960;
  camera.intrinsics.params = {1.05, 420.5, 418.25, 641.5, 479.75, 0.0, -0.21, 0.043, 1.5e-3,
                              -7.5e-4, 0.0};
  return camera;
}

void ExpectSameCamera(const CameraModel& a, const CameraModel& b) {
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
    EXPECT_NEAR(a.intrinsics.params[i], b.intrinsics.params[i],
                1e-12 * std::max(1.0, std::abs(a.intrinsics.params[i])))
        << UnifiedIntrinsics::kNames[i];
  }
}

TEST(ModelIo, OpenCvRoundTripIsExactWithoutK5) {
  CameraModel camera = Camera();
  camera.intrinsics.alpha() = 1e-3;  // OpenCV has skew
  std::vector<std::string> warnings;
  const std::string text = ToOpenCvOmnidir(camera, &warnings);
  EXPECT_TRUE(warnings.empty());
  ExpectSameCamera(camera, FromOpenCvOmnidir(text));
}

TEST(ModelIo, OpenCvExportProjectsLikeCvOmnidir) {
  const CameraModel camera = Camera();
  cv::FileStorage fs(ToOpenCvOmnidir(camera, nullptr),
                     cv::FileStorage::READ | cv::FileStorage::MEMORY);
  cv::Mat k, d;
  fs["camera_matrix"] >> k;
  fs["distortion_coefficients"] >> d;
  const double xi = fs["xi"];
  const std::vector<cv::Point3d> points = {{0.3, -0.2, 0.5}, {-1.0, 0.4, -0.1}, {0.1, 0.9, 0.2}};
  std::vector<cv::Point2d> projected;
  cv::omnidir::projectPoints(points, projected, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), k, xi, d);
  for (size_t i = 0; i < points.size(); ++i) {
    const auto ours = Project(camera.intrinsics, {points[i].x, points[i].y, points[i].z});
    ASSERT_TRUE(ours);
    EXPECT_NEAR(ours->x(), projected[i].x, 1e-9);
    EXPECT_NEAR(ours->y(), projected[i].y, 1e-9);
  }
}

TEST(ModelIo, KalibrRoundTripIsExactWithoutK5AndSkew) {
  const CameraModel camera = Camera();
  std::vector<std::string> warnings;
  const std::string text = ToKalibrOmniRadtan(camera, &warnings, "cam1");
  EXPECT_TRUE(warnings.empty());
  ExpectSameCamera(camera, FromKalibrOmniRadtan(text, "cam1"));
  EXPECT_THROW(FromKalibrOmniRadtan(text, "cam0"), InvalidArgument);
}

TEST(ModelIo, ExportsSayWhatTheyDrop) {
  CameraModel camera = Camera();
  camera.intrinsics.k(5) = 0.01;
  camera.intrinsics.alpha() = 0.002;
  std::vector<std::string> warnings;
  const std::string opencv = ToOpenCvOmnidir(camera, &warnings);
  ASSERT_EQ(warnings.size(), 1u);  // k5 only: OpenCV has skew
  EXPECT_NE(warnings[0].find("k5"), std::string::npos);
  EXPECT_NE(opencv.find("WARNING"), std::string::npos);
  const std::string kalibr = ToKalibrOmniRadtan(camera, &warnings);
  ASSERT_EQ(warnings.size(), 2u);
  EXPECT_NE(warnings[1].find("skew"), std::string::npos);
  EXPECT_NE(kalibr.find("# WARNING: k5"), std::string::npos);
  EXPECT_EQ(FromKalibrOmniRadtan(kalibr).intrinsics.k(5), 0.0);
}

TEST(ModelIo, ReadsKalibrCamchainWithTwoCameras) {
  const std::string text =
      "cam0:\n  camera_model: omni\n  intrinsics: [0.8, 300, 301, 320.5, 240.5]\n"
      "  distortion_model: radtan\n  distortion_coeffs: [-0.1, 0.01, 0.001, 0.002]\n"
      "  resolution: [640, 480]\n  rostopic: /cam0/image_raw\n"
      "cam1:\n  camera_model: pinhole\n  intrinsics: [300, 301, 320.5, 240.5]\n"
      "  distortion_model: radtan\n  distortion_coeffs: [0, 0, 0, 0]\n";
  const CameraModel camera = FromKalibrOmniRadtan(text);
  EXPECT_EQ(camera.intrinsics.xi(), 0.8);
  EXPECT_EQ(camera.intrinsics.k(4), 0.002);
  EXPECT_EQ(camera.width, 640);
  EXPECT_THROW(FromKalibrOmniRadtan(text, "cam1"), InvalidArgument);  // pinhole
}

TEST(ModelIo, MalformedInputsThrow) {
  EXPECT_THROW(FromOpenCvOmnidir("%YAML:1.0\nxi: 1.0\n"), InvalidArgument);
  EXPECT_THROW(FromOpenCvOmnidir("not a document"), InvalidArgument);
  EXPECT_THROW(FromKalibrOmniRadtan("cam0:\n  camera_model: omni\n"), InvalidArgument);
  EXPECT_THROW(FromKalibrOmniRadtan(
                   "cam0:\n  camera_model: omni\n  intrinsics: [1, 2, x, 4, 5]\n"
                   "  distortion_model: radtan\n  distortion_coeffs: [0, 0, 0, 0]\n"),
               InvalidArgument);
}

}  // namespace
}  // namespace omnirig
