// The board motion model's pieces (relpose_motion.h) on small synthetic cases: the link cost,
// the estimator of Sigma with and without motion, and the rig fit and covariance with the prior.

#include "engine/stereo/relpose_motion.h"

#include <cmath>
#include <memory>

#include <gtest/gtest.h>

#include "engine/stereo/relpose_motion_scene.h"
#include "engine/util/check.h"

namespace omnirig {
namespace {

using namespace relpose_test;  // NOLINT: the shared test scenes

// The scene's pairs as the refinement sees them (ids are the board's, orders as detected).
std::vector<RigPairCorners> CornersOf(const Scene& scene) {
  const std::vector<Eigen::Vector3d> object = scene.board.ObjectPoints();
  std::vector<RigPairCorners> corners;
  for (const StereoBoardPair& pair : scene.pairs) {
    RigPairCorners c;
    for (size_t k = 0; k < pair.cam0.corner_ids.size(); ++k) {
      c.points_in_board0.push_back(object[pair.cam0.corner_ids[k]]);
      c.pixels0.push_back(pair.cam0.corners_px[k]);
    }
    for (size_t k = 0; k < pair.cam1.corner_ids.size(); ++k) {
      c.points_in_board1.push_back(object[pair.cam1.corner_ids[k]]);
      c.pixels1.push_back(pair.cam1.corners_px[k]);
    }
    corners.push_back(c);
  }
  return corners;
}

TEST(BoardMotionLinkCost, IsZeroOnTheRigsPredictionAndWhitensAKnownMotion) {
  BoardSpec board;
  board.cols = 9;
  board.rows = 6;
  board.square_size_m = 0.02423;
  const Rigid3d rig = VerticalRig();
  const Rigid3d cam0_from_board = BoardPose(board, 40.0, 0.7, 20.0, 0.02);
  const Eigen::Vector3d rotation_vector(0.002, -0.004, 0.003), shift(4e-4, -2e-4, 7e-4);
  const Rigid3d moved = MoveBoard(board, cam0_from_board, rotation_vector, shift);
  BoardMotionPrior prior;
  prior.rotation_std_rad = 0.005;
  prior.translation_std_m = 5e-4;
  prior.corner_noise_px = 0.12;
  std::unique_ptr<ceres::CostFunction> cost(
      BoardMotionLinkCost::Create(BoardCentreOf(board), prior));
  const auto b = cam0_from_board.ToParams(), r = rig.ToParams();
  for (const bool board_moved : {false, true}) {
    const auto c = (rig.Inverse() * (board_moved ? moved : cam0_from_board)).ToParams();
    const double* parameters[3] = {b.data(), r.data(), c.data()};
    double residual[6];
    ASSERT_TRUE(cost->Evaluate(parameters, residual, nullptr));
    const Eigen::Map<const Eigen::Matrix<double, 6, 1>> e(residual);
    if (!board_moved) {
      EXPECT_LT(e.norm(), 1e-12);
      continue;
    }
    // In cam0's frame, weighted by corner noise / std.
    EXPECT_NEAR((e.head<3>() - 0.12 / 0.005 * rotation_vector).norm(), 0.0, 1e-9);
    EXPECT_NEAR((e.tail<3>() - 0.12 / 5e-4 * shift).norm(), 0.0, 1e-9);
  }
  BoardMotionPrior zero = prior;
  zero.translation_std_m = 0.0;
  EXPECT_THROW(BoardMotionLinkCost::Create(BoardCentreOf(board), zero), InvalidArgument);
}

TEST(BoardMotionEstimator, StillBoardsGiveNoModel) {
  const Scene scene = MakeMotionScene(MotionSceneOptions(), 11);
  const BoardMotionEstimate estimate =
      EstimateBoardMotion(scene.rig, CornersOf(scene), {0.12, 0.12}, BoardMotionOptions());
  EXPECT_EQ(estimate.num_pairs, 24);
  EXPECT_FALSE(estimate.used);
  EXPECT_EQ(estimate.rotation_std_rad, 0.0);
  EXPECT_EQ(estimate.translation_std_m, 0.0);
  EXPECT_EQ(estimate.dof, 6 * 23);
  // Without motion the statistic is about chi^2 on its dof.
  EXPECT_LT(estimate.statistic, estimate.limit);
  EXPECT_GT(estimate.statistic, 0.5 * estimate.dof);
}

// 10 rigs of 96 pairs, the rig known. Per rig the translation's std is recovered to about
// 12 % (the own fits' noise along the line of sight, 0.6 mm per axis on average, is larger than
// the motion), the rotation's to about 9 %; the means over the 10 rigs to a third of that.
TEST(BoardMotionEstimator, KnownMotionIsRecovered) {
  MotionSceneOptions options;
  options.num_pairs = 96;
  options.rotation_std_deg = 0.3;
  options.translation_std_m = 5e-4;
  const int num_seeds = 10;
  double mean_rotation_deg = 0.0, mean_translation_m = 0.0;
  for (int seed = 0; seed < num_seeds; ++seed) {
    const Scene scene = MakeMotionScene(options, 100 + seed);
    const BoardMotionEstimate estimate =
        EstimateBoardMotion(scene.rig, CornersOf(scene), {0.12, 0.12}, BoardMotionOptions());
    ASSERT_TRUE(estimate.used);
    EXPECT_GT(estimate.statistic, 3.0 * estimate.limit);
    EXPECT_NEAR(estimate.rotation_std_rad * kDegPerRad, 0.3, 0.3 * 0.4);
    EXPECT_NEAR(estimate.translation_std_m, 5e-4, 5e-4 * 0.5);
    mean_rotation_deg += estimate.rotation_std_rad * kDegPerRad / num_seeds;
    mean_translation_m += estimate.translation_std_m / num_seeds;
  }
  EXPECT_NEAR(mean_rotation_deg, 0.3, 0.3 * 0.1);
  EXPECT_NEAR(mean_translation_m, 5e-4, 5e-4 * 0.12);
}

TEST(BoardMotionEstimator, RotationOnlyMotionFloorsTheTranslation) {
  MotionSceneOptions options;
  options.num_pairs = 48;
  options.rotation_std_deg = 0.5;
  const Scene scene = MakeMotionScene(options, 13);
  const BoardMotionEstimate estimate =
      EstimateBoardMotion(scene.rig, CornersOf(scene), {0.12, 0.12}, BoardMotionOptions());
  ASSERT_TRUE(estimate.used);
  EXPECT_NEAR(estimate.rotation_std_rad * kDegPerRad, 0.5, 0.5 * 0.2);
  // A rotation about the centre moves the centre by nothing: the translation's estimate is
  // small, and never below the floor.
  EXPECT_GE(estimate.translation_std_m, 0.1 * estimate.noise_translation_std_m - 1e-15);
  EXPECT_LT(estimate.translation_std_m, 1.5 * estimate.noise_translation_std_m);
}

// The estimate with the model on equals the estimate with it off, bit for bit, on still boards;
// with motion it is used, and the covariance includes it.
TEST(BoardMotionRelativePose, StillBoardsChangeNothingAndMovingBoardsWidenTheStd) {
  MotionSceneOptions options;
  options.num_pairs = 12;
  const Scene still = MakeMotionScene(options, 21);
  RelativePoseOptions on, off;
  on.model_board_motion = true;
  off.model_board_motion = false;
  const RelativePoseReport a = Estimate(still, on), b = Estimate(still, off);
  ASSERT_TRUE(a.success && b.success) << a.message << b.message;
  EXPECT_FALSE(a.board_motion.used);
  EXPECT_EQ(a.rig.cam0_from_cam1.translation, b.rig.cam0_from_cam1.translation);
  EXPECT_EQ(a.rig.cam0_from_cam1.rotation.coeffs(), b.rig.cam0_from_cam1.rotation.coeffs());
  EXPECT_EQ(a.baseline_std_m, b.baseline_std_m);
  EXPECT_EQ(a.rms_px, b.rms_px);

  options.rotation_std_deg = 0.3;
  options.translation_std_m = 5e-4;
  const Scene moving = MakeMotionScene(options, 22);
  const RelativePoseReport c = Estimate(moving, on), d = Estimate(moving, off);
  ASSERT_TRUE(c.success && d.success) << c.message << d.message;
  ASSERT_TRUE(c.board_motion.used);
  EXPECT_FALSE(d.board_motion.used);
  EXPECT_EQ(d.board_motion.num_pairs, 0);  // not estimated when off
  EXPECT_GT(c.baseline_std_m, 2.0 * d.baseline_std_m);
  EXPECT_GT(c.rotation_std_deg, 2.0 * d.rotation_std_deg);
  // The RMS means the same with the model (one board pose per pair through the rig): eq. 20
  // minimises it, the model's rig is a little different.
  EXPECT_GE(c.rms_px, 0.999 * d.rms_px);
  EXPECT_LT(c.rms_px, 1.05 * d.rms_px);
}

TEST(BoardMotionOptions, CheckNamesTheField) {
  BoardMotionOptions options;
  options.significance = 0.0;
  try {
    options.Check();
    FAIL() << "expected InvalidArgument";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("board_motion.significance"), std::string::npos);
  }
}

}  // namespace
}  // namespace omnirig
