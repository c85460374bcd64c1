#include "engine/synth/presets.h"

#include <cmath>
#include <set>

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig::synth {
namespace {

TEST(Presets, BoardPosesKeepTheBoardInsideTheAnnulusAllAround) {
  const SynthCamera camera = DefaultCamera(640, 480);
  const CheckerboardSpec board;
  const BoardPoseOptions options;
  constexpr int kViews = 12;
  std::set<int> octants;
  for (int view = 0; view < kViews; ++view) {
    const Rigid3d cam_from_board =
        SampleBoardPose({camera}, {Rigid3d()}, board, options, view, kViews, 3);
    for (const Eigen::Vector3d& corner : BoardOutline(board)) {
      EXPECT_TRUE(ProjectVisible(camera, cam_from_board * corner, options.min_margin_px));
    }
    for (const Eigen::Vector2d& pixel : ProjectBoardCorners(camera, cam_from_board, board)) {
      EXPECT_TRUE(InAnnulus(camera, pixel, options.min_margin_px));
    }
    const Eigen::Vector3d centre = cam_from_board * Eigen::Vector3d(0.14, 0.10, 0.0);
    EXPECT_GE(centre.norm(), options.min_distance_m - 0.01);
    EXPECT_LE(centre.norm(), options.max_distance_m + 0.01);
    // The printed side faces the camera, tilted by at most max_tilt_deg.
    const Eigen::Vector3d normal = cam_from_board.rotation * Eigen::Vector3d::UnitZ();
    const double tilt_deg = std::acos(normal.dot(centre.normalized())) * 180.0 / M_PI;
    EXPECT_LE(tilt_deg, options.max_tilt_deg + 1.0);
    const double azimuth = std::atan2(centre.y(), centre.x()) + M_PI;
    octants.insert(static_cast<int>(azimuth / (M_PI / 4)) % 8);
  }
  EXPECT_EQ(octants.size(), 8u);  // views all around the mirror
  // Deterministic in (seed, index).
  const Rigid3d a = SampleBoardPose({camera}, {Rigid3d()}, board, options, 4, kViews, 3);
  const Rigid3d b = SampleBoardPose({camera}, {Rigid3d()}, board, options, 4, kViews, 3);
  EXPECT_EQ(a.translation, b.translation);
}

TEST(Presets, ImpossibleBoardThrows) {
  CheckerboardSpec huge;
  huge.square_size_m = 0.5;
  EXPECT_THROW(
      SampleBoardPose({DefaultCamera(640, 480)}, {Rigid3d()}, huge, BoardPoseOptions(), 0, 1, 0),
      InvalidArgument);
}

TEST(Presets, MonoCalibrationSetHoldsConsistentGroundTruth) {
  MonoCalibrationOptions options;
  options.num_views = 2;
  options.width = 320;
  options.height = 240;
  options.poses.min_square_px = 3.0;
  options.render.supersampling = 1;
  int reports = 0;
  ProgressSink progress;
  progress.report = [&](double, const std::string&, const std::string&) { ++reports; };
  const MonoCalibrationSet set = MakeMonoCalibrationSet(options, progress);
  EXPECT_EQ(reports, 2);
  ASSERT_EQ(set.images.size(), 2u);
  EXPECT_EQ(set.names[1], "view_001");
  EXPECT_EQ(set.images[0].cols, 320);
  ASSERT_EQ(set.corners_px[1].size(), static_cast<size_t>(set.board.cols * set.board.rows));
  const auto expected = ProjectBoardCorners(set.camera, set.cam_from_board[1], set.board);
  EXPECT_EQ(set.corners_px[1], expected);
  options.num_views = 0;
  EXPECT_THROW(MakeMonoCalibrationSet(options), InvalidArgument);
}

TEST(Presets, SameSeedSameSet) {
  MonoCalibrationOptions options;
  options.num_views = 1;
  options.width = 320;
  options.height = 240;
  options.poses.min_square_px = 3.0;
  options.render.supersampling = 1;
  options.render.noise_sigma = 2.0;
  options.seed = 5;
  const MonoCalibrationSet a = MakeMonoCalibrationSet(options);
  const MonoCalibrationSet b = MakeMonoCalibrationSet(options);
  EXPECT_EQ(cv::norm(a.images[0], b.images[0], cv::NORM_INF), 0.0);
  EXPECT_EQ(a.cam_from_board[0].translation, b.cam_from_board[0].translation);
  options.seed = 6;
  const MonoCalibrationSet c = MakeMonoCalibrationSet(options);
  EXPECT_NE(a.cam_from_board[0].translation, c.cam_from_board[0].translation);
}

TEST(Presets, CancellationStopsTheRun) {
  MonoCalibrationOptions options;
  options.num_views = 3;
  options.width = 320;
  options.height = 240;
  options.poses.min_square_px = 3.0;
  options.render.supersampling = 1;
  ProgressSink progress;
  progress.is_cancelled = [] { return true; };
  EXPECT_THROW(MakeMonoCalibrationSet(options, progress), Cancelled);
}

TEST(Presets, StereoBoardSetSeesTheBoardInBothCameras) {
  StereoBoardOptions options;
  options.num_pairs = 1;
  options.width = 320;
  options.height = 240;
  options.poses.min_square_px = 3.0;
  options.render.supersampling = 1;
  const StereoBoardSet set = MakeStereoBoardSet(options);
  EXPECT_NEAR(set.rig.cam0_from_cam1.translation.norm(), 0.1, 1e-12);
  EXPECT_EQ(set.rig.cam1.intrinsics.params, set.cameras[1].model.intrinsics.params);
  ASSERT_EQ(set.images[1].size(), 1u);
  const Rigid3d cam1_from_board = set.rig.cam0_from_cam1.Inverse() * set.cam0_from_board[0];
  for (size_t i = 0; i < set.corners_px[1][0].size(); ++i) {
    const Eigen::Vector3d point = BoardCorners(set.board)[i];
    const auto pixel = Project(set.rig.cam1.intrinsics, cam1_from_board * point);
    ASSERT_TRUE(pixel.has_value());
    EXPECT_LT((*pixel - set.corners_px[1][0][i]).norm(), 1e-9);
    EXPECT_TRUE(InAnnulus(set.cameras[0], set.corners_px[0][0][i]));
  }
}

}  // namespace
}  // namespace omnirig::synth
