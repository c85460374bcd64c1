#include "engine/calib/model_io.h"

#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <sstream>

#include <gtest/gtest.h>
#include <opencv2/ccalib/omnidir.hpp>

#include "testing/calib/model_import.h"

namespace omnirig {
namespace {

CameraModel Camera() {
  CameraModel camera;
  camera.width = 1280;
  camera.height = 960;
  camera.intrinsics.params = {1.05,  420.5, 418.25, 641.5,   479.75, 0.0,
                              -0.21, 0.043, 1.5e-3, -7.5e-4, 0.0};
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

TEST(ModelIo, KalibrCamchainRoundTripKeepsBothCamerasAndTheExtrinsic) {
  StereoRig rig;
  rig.cam0 = Camera();
  rig.cam1 = Camera();
  rig.cam1.intrinsics.gamma_u() = 431.0;
  rig.cam1.intrinsics.xi() = 0.97;
  rig.cam0_from_cam1 =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.01, Eigen::Vector3d(1, 0.5, 0.2).normalized())),
              Eigen::Vector3d(0.002, -0.001, 0.1));
  std::vector<std::string> warnings;
  const std::string text = ToKalibrCamchain(rig, &warnings);
  EXPECT_TRUE(warnings.empty());
  EXPECT_NE(text.find("T_cn_cnm1"), std::string::npos) << text;
  // Each camera names the other as the one it overlaps with, as Kalibr writes them.
  EXPECT_NE(text.find("cam0:\n  cam_overlaps: [1]\n"), std::string::npos) << text;
  EXPECT_NE(text.find("  cam_overlaps: [0]\n", text.find("cam1:\n")), std::string::npos) << text;
  const StereoRig back = FromKalibrCamchain(text);
  ExpectSameCamera(rig.cam0, back.cam0);
  ExpectSameCamera(rig.cam1, back.cam1);
  // T_cn_cnm1 maps cam0's points into cam1: a point 1 m along cam0's axis.
  const Eigen::Vector3d point_in_cam0(0.3, -0.2, 1.0);
  EXPECT_LT((back.cam0_from_cam1.Inverse() * point_in_cam0 -
             rig.cam0_from_cam1.Inverse() * point_in_cam0)
                .norm(),
            1e-12);
  // Kalibr's own convention, read straight from the text: the translation column of
  // T_cn_cnm1 is cam1_from_cam0's translation.
  const Eigen::Vector3d t = rig.cam0_from_cam1.Inverse().translation;
  std::ostringstream first_row_end;
  first_row_end << std::setprecision(17) << t.x() << "], [";
  EXPECT_NE(text.find(first_row_end.str()), std::string::npos) << text;
  EXPECT_THROW(FromKalibrCamchain(ToKalibrOmniRadtan(rig.cam0, nullptr, "cam0") +
                                  ToKalibrOmniRadtan(rig.cam1, nullptr, "cam1")),
               InvalidArgument);
}

// A camchain as Kalibr writes it: 4x4 matrices in block style, cam_overlaps, rostopic.
TEST(ModelIo, ReadsKalibrsOwnCamchainLayout) {
  const StereoRig rig = FromKalibrCamchain(
      "cam0:\n  cam_overlaps: [1]\n  camera_model: omni\n"
      "  distortion_coeffs: [-0.0617, 0.0125, 0.0004, -0.0003]\n  distortion_model: radtan\n"
      "  intrinsics: [0.94, 253.4, 254.6, 514.2, 386.1]\n  resolution: [1024, 768]\n"
      "  rostopic: /rig/cam0/image_raw\n"
      "cam1:\n  T_cn_cnm1:\n  - [1.0, 0.0, 0.0, 0.001]\n  - [0.0, 1.0, 0.0, 0.0]\n"
      "  - [0.0, 0.0, 1.0, -0.1]\n  - [0.0, 0.0, 0.0, 1.0]\n  cam_overlaps: [0]\n"
      "  camera_model: omni\n  distortion_coeffs: [-0.06, 0.012, 0.0003, -0.0002]\n"
      "  distortion_model: radtan\n  intrinsics: [0.95, 252.0, 253.1, 511.8, 383.9]\n"
      "  resolution: [1024, 768]\n  rostopic: /rig/cam1/image_raw\n");
  EXPECT_DOUBLE_EQ(rig.cam0.intrinsics.gamma_u(), 253.4);
  EXPECT_DOUBLE_EQ(rig.cam1.intrinsics.xi(), 0.95);
  EXPECT_EQ(rig.cam1.width, 1024);
  // T_cn_cnm1 is cam1_from_cam0: cam1 0.1 m along cam0's +z (below it), 1 mm along -x.
  EXPECT_LT((rig.cam0_from_cam1.translation - Eigen::Vector3d(-0.001, 0, 0.1)).norm(), 1e-12);
}

TEST(ModelIo, MalformedInputsThrow) {
  EXPECT_THROW(FromOpenCvOmnidir("%YAML:1.0\nxi: 1.0\n"), InvalidArgument);
  EXPECT_THROW(FromOpenCvOmnidir("not a document"), InvalidArgument);
  EXPECT_THROW(FromKalibrOmniRadtan("cam0:\n  camera_model: omni\n"), InvalidArgument);
  EXPECT_THROW(
      FromKalibrOmniRadtan("cam0:\n  camera_model: omni\n  intrinsics: [1, 2, x, 4, 5]\n"
                           "  distortion_model: radtan\n  distortion_coeffs: [0, 0, 0, 0]\n"),
      InvalidArgument);
  // A camchain is a file a user uploads: sizes and numbers out of range are refused, not cast.
  const std::string camera =
      "cam0:\n  camera_model: omni\n  intrinsics: [0.9, 300, 300, 320, 240]\n"
      "  distortion_model: radtan\n  distortion_coeffs: [0, 0, 0, 0]\n";
  EXPECT_NO_THROW(FromKalibrOmniRadtan(camera + "  resolution: [640, 480]\n"));
  EXPECT_THROW(FromKalibrOmniRadtan(camera + "  resolution: [1e300, 480]\n"), InvalidArgument);
  EXPECT_THROW(FromKalibrOmniRadtan(camera + "  resolution: [640.5, 480]\n"), InvalidArgument);
  EXPECT_THROW(FromKalibrOmniRadtan(camera + "  resolution: [-640, 480]\n"), InvalidArgument);
}

// Writes two views of a 3 x 2 board (spacing 30 mm, stored in mm) as OpenCV FileStorage.
std::filesystem::path WriteCornerFile(const std::string& name, double off_grid_x_mm) {
  const std::filesystem::path path = std::filesystem::temp_directory_path() / name;
  cv::FileStorage fs(path.string(), cv::FileStorage::WRITE);
  std::vector<cv::Mat> object_points, image_points;
  for (int v = 0; v < 2; ++v) {
    cv::Mat object(6, 1, CV_64FC3), image(6, 1, CV_32FC2);
    for (int i = 0; i < 6; ++i) {
      // Stored in reverse order: ids come from the positions, not from the order.
      const int id = 5 - i;
      object.at<cv::Vec3d>(i) = cv::Vec3d(30.0 * (id % 3), 30.0 * (id / 3), 0.0);
      image.at<cv::Vec2f>(i) = cv::Vec2f(100.0f * v + id, 0.5f * id);
    }
    object_points.push_back(object);
    image_points.push_back(image);
  }
  object_points[1].at<cv::Vec3d>(2)[0] += off_grid_x_mm;
  fs << "objectPoints" << object_points << "imagePoints" << image_points;
  return path;
}

TEST(ModelIo, ReadsOpenCvCornerViews) {
  BoardSpec board;
  board.cols = 3;
  board.rows = 2;
  board.square_size_m = 0.03;
  const auto path = WriteCornerFile("omnirig_model_io_corners.yml", 0.0);
  const std::vector<CalibrationView> views = ReadOpenCvCornerViews(path.string(), board, 1e-3);
  ASSERT_EQ(views.size(), 2u);
  EXPECT_EQ(views[1].name, "view1");
  EXPECT_TRUE(views[1].detection.found);
  ASSERT_EQ(views[1].detection.corner_ids.size(), 6u);
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(views[1].detection.corner_ids[i], 5 - i);
    EXPECT_EQ(views[1].detection.corners_px[i], Eigen::Vector2d(100.0 + (5 - i), 0.5 * (5 - i)));
  }
  // In metres the same points are 1000 squares apart: off the grid.
  EXPECT_THROW(ReadOpenCvCornerViews(path.string(), board), InvalidArgument);
  std::filesystem::remove(path);
}

TEST(ModelIo, OpenCvCornerViewsRejectBadFiles) {
  BoardSpec board;
  board.cols = 3;
  board.rows = 2;
  board.square_size_m = 0.03;
  const auto off_grid = WriteCornerFile("omnirig_model_io_off_grid.yml", 7.0);
  EXPECT_THROW(ReadOpenCvCornerViews(off_grid.string(), board, 1e-3), InvalidArgument);
  std::filesystem::remove(off_grid);
  EXPECT_THROW(ReadOpenCvCornerViews("/nonexistent/corners.yml", board), InvalidArgument);
  board.cols = 2;  // the points' third column falls off a 2 x 2 board
  const auto path = WriteCornerFile("omnirig_model_io_small_board.yml", 0.0);
  EXPECT_THROW(ReadOpenCvCornerViews(path.string(), board, 1e-3), InvalidArgument);
  std::filesystem::remove(path);
}

// The two real corner files of ../shared/data/real (skipped when absent).
TEST(ModelIo, ReadsTheRealCornerFiles) {
  const char* source = std::getenv("OMNIRIG_SOURCE_DIR");
  const std::filesystem::path real =
      std::filesystem::path(source ? source : ".") / ".." / "shared" / "data" / "real";
  const auto tutorial = real / "opencv-omnidir-tutorial" / "omni_calib_data.xml";
  const auto vmr = real / "ocamcalib-vmr" / "toolbox_corners.yml";
  if (!std::filesystem::exists(tutorial) || !std::filesystem::exists(vmr)) {
    GTEST_SKIP() << "real data not found at " << real;
  }
  BoardSpec board;
  board.cols = 6;
  board.rows = 9;
  board.square_size_m = 0.2;  // the tutorial's spacing, unit not stated
  const auto tutorial_views = ReadOpenCvCornerViews(tutorial.string(), board);
  ASSERT_EQ(tutorial_views.size(), 15u);
  for (const auto& view : tutorial_views) EXPECT_EQ(view.detection.corner_ids.size(), 54u);
  // The toolbox's x axis runs along the board's 7-corner side.
  board.cols = 7;
  board.rows = 6;
  board.square_size_m = 0.03;
  const auto vmr_views = ReadOpenCvCornerViews(vmr.string(), board, 1e-3);  // stored in mm
  ASSERT_EQ(vmr_views.size(), 10u);
  for (const auto& view : vmr_views) EXPECT_EQ(view.detection.corner_ids.size(), 42u);
}

}  // namespace
}  // namespace omnirig
