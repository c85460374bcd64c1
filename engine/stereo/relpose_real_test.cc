// The relative pose on real fisheye stereo pairs (label integration): detection, per-camera
// calibration and the rig, against the reference baseline of the data's own repository
// (cv::fisheye: 109.96 mm; cv::fisheye::stereoCalibrate gives 109.76 mm, so the reference is
// itself uncertain by a few tenths of a percent).

#include <cstdlib>
#include <filesystem>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "engine/calib/calibrate.h"
#include "engine/calib/detect.h"
#include "engine/stereo/relative_pose.h"

namespace omnirig {
namespace {

std::filesystem::path DataDir() {
  const char* source = std::getenv("OMNIRIG_SOURCE_DIR");
  return std::filesystem::path(source != nullptr ? source : ".") / ".." / "shared" / "data" /
         "real" / "fisheye-stereo-pairs";
}

CameraModel CalibrateCamera(const std::vector<StereoBoardPair>& pairs, int camera,
                            const BoardSpec& board) {
  std::vector<CalibrationView> views;
  for (const StereoBoardPair& pair : pairs) {
    views.push_back({pair.name, camera == 0 ? pair.cam0 : pair.cam1});
  }
  return Calibrate(views, 960, 600, board, CalibrationOptions(), ProgressSink()).camera;
}

TEST(RelativePoseReal, FisheyePairsGiveTheReferenceBaseline) {
  const std::filesystem::path dir = DataDir();
  if (!std::filesystem::is_directory(dir)) {
    GTEST_SKIP() << "real data not found at " << dir << " (../shared/data/real)";
  }
  BoardSpec board;
  board.cols = 9;
  board.rows = 6;
  board.square_size_m = 0.02423;
  std::vector<StereoBoardPair> pairs;
  for (int i = 1; i <= 29; ++i) {
    const cv::Mat left =
        cv::imread((dir / ("left" + std::to_string(i) + ".jpg")).string(), cv::IMREAD_GRAYSCALE);
    const cv::Mat right =
        cv::imread((dir / ("right" + std::to_string(i) + ".jpg")).string(), cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(left.empty() || right.empty()) << "pair " << i;
    pairs.push_back({"pair" + std::to_string(i), DetectBoard(left, board, DetectOptions()),
                     DetectBoard(right, board, DetectOptions())});
  }
  const CameraModel cam0 = CalibrateCamera(pairs, 0, board);
  const CameraModel cam1 = CalibrateCamera(pairs, 1, board);
  RelativePoseOptions options;
  options.refine_intrinsics = true;
  const RelativePoseReport report = EstimateRelativePose(cam0, cam1, board, pairs, options);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_GE(report.num_pairs_used, 25);
  EXPECT_LT(report.rms_px, 0.5);
  // Left camera = cam0: the right camera sits ~110 mm along cam0's +x.
  EXPECT_GT(report.rig.cam0_from_cam1.translation.x(), 0.1);
  EXPECT_NEAR(report.baseline_m, 0.10996, 0.01 * 0.10996);
  EXPECT_LT(RotationDistanceRad(report.rig.cam0_from_cam1.rotation, Eigen::Quaterniond::Identity()),
            3.0 * M_PI / 180.0);
}

}  // namespace
}  // namespace omnirig
