#include "engine/calib/svp.h"

#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

namespace omnirig {
namespace {

CameraModel Camera() {
  CameraModel camera;
  camera.width = 800;
  camera.height = 600;
  camera.intrinsics.params = {0.9, 240, 240, 402.5, 297.25, 0, -0.05, 0.01, 0, 0, 0};
  return camera;
}

// A bright mirror disk on black, centred at `centre` with `radius` (pixels).
cv::Mat MirrorImage(const cv::Point2d& centre, double radius) {
  cv::Mat image(600, 800, CV_8UC1, cv::Scalar(10));
  cv::circle(image, cv::Point(cvRound(centre.x * 16), cvRound(centre.y * 16)), cvRound(radius * 16),
             cv::Scalar(200), -1, cv::LINE_AA, 4);
  return image;
}

TEST(Svp, FindsTheRimWherePredictedAndMeasuresAnOffset) {
  const CameraModel camera = Camera();
  const MirrorRim rim{0.03, 0.01};
  const SvpCheckReport predicted_only =
      CheckSingleViewpoint(cv::Mat(600, 800, CV_8UC1, cv::Scalar(10)), camera, rim, {});
  EXPECT_FALSE(predicted_only.found_circle_px);
  ASSERT_TRUE(predicted_only.predicted_circle_px);
  const Eigen::Vector3d circle = *predicted_only.predicted_circle_px;
  EXPECT_NEAR(circle.x(), 402.5, 1e-6);  // radial model: the rim centres on the principal point

  const SvpCheckReport aligned =
      CheckSingleViewpoint(MirrorImage({circle.x(), circle.y()}, circle.z()), camera, rim, {});
  ASSERT_TRUE(aligned.found_circle_px) << aligned.reason;
  EXPECT_LT(aligned.centre_offset_px, 0.3);
  EXPECT_LT(std::abs(aligned.radius_offset_px), 0.6);

  const SvpCheckReport shifted = CheckSingleViewpoint(
      MirrorImage({circle.x() + 6.0, circle.y() - 8.0}, circle.z() + 5.0), camera, rim, {});
  ASSERT_TRUE(shifted.found_circle_px) << shifted.reason;
  EXPECT_NEAR(shifted.centre_offset_px, 10.0, 0.5);
  EXPECT_NEAR(shifted.radius_offset_px, 5.0, 0.6);
  EXPECT_FALSE(DrawSvpOverlay(MirrorImage({400, 300}, 200), shifted).empty());
}

// Without the mirror's dimensions: the rim is found around the principal point among scene
// edges (a board-like pattern inside the disk), and its centre's offset reported.
TEST(Svp, DetectsTheRimAroundThePrincipalPoint) {
  const CameraModel camera = Camera();  // principal point (402.5, 297.25)
  cv::Mat image = MirrorImage({408.0, 293.0}, 230.0);
  for (int i = 0; i < 12; ++i) {  // scene: dark squares inside the mirror disk
    const int u = 300 + 17 * i, v = 220 + (i % 3) * 40;
    cv::rectangle(image, cv::Rect(u, v, 12, 12), cv::Scalar(30), -1);
  }
  const SvpCheckReport report = DetectRim(image, camera, {});
  ASSERT_TRUE(report.found_circle_px) << report.reason;
  EXPECT_FALSE(report.predicted_circle_px);
  EXPECT_NEAR(report.found_circle_px->x(), 408.0, 0.3);
  EXPECT_NEAR(report.found_circle_px->y(), 293.0, 0.3);
  EXPECT_NEAR(report.found_circle_px->z(), 230.0, 0.6);
  EXPECT_NEAR(report.principal_point_offset_px, std::hypot(5.5, 4.25), 0.3);
  EXPECT_FALSE(DrawSvpOverlay(image, report).empty());
  // A flat image has no rim: a reason, not an exception.
  const SvpCheckReport flat =
      DetectRim(cv::Mat(600, 800, CV_8UC3, cv::Scalar::all(90)), camera, {});
  EXPECT_FALSE(flat.found_circle_px);
  EXPECT_FALSE(flat.reason.empty());
}

TEST(Svp, BadInputsThrow) {
  EXPECT_THROW(CheckSingleViewpoint(cv::Mat(), Camera(), {0.03, 0.01}, {}), InvalidArgument);
  EXPECT_THROW(CheckSingleViewpoint(cv::Mat(600, 800, CV_8UC1), Camera(), {0.0, 0.01}, {}),
               InvalidArgument);
}

}  // namespace
}  // namespace omnirig
