#include "engine/rig/relative_pose.h"

#include <cmath>
#include <random>

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include "engine/geometry/reprojection_cost.h"
#include "engine/rig/relpose_corner_order.h"
#include "engine/rig/relpose_linear.h"
#include "testing/rig/relpose_test_scene.h"

namespace omnirig {
namespace {

using namespace relpose_test;  // NOLINT: the shared test scenes

TEST(RelposeLinear, ProjectToRotationIsNearestRotation) {
  const Eigen::Matrix3d truth =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  EXPECT_LT((ProjectToRotation(truth) - truth).norm(), 1e-12);
  Eigen::Matrix3d noisy = truth;
  noisy(0, 1) += 0.01;
  noisy(2, 0) -= 0.02;
  const Eigen::Matrix3d projected = ProjectToRotation(noisy);
  EXPECT_LT((projected * projected.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(projected.determinant(), 1.0, 1e-12);
  EXPECT_LT((projected - truth).norm(), 0.03);
  // A reflection is mapped to a proper rotation, not kept.
  EXPECT_NEAR(ProjectToRotation(-Eigen::Matrix3d::Identity()).determinant(), 1.0, 1e-12);
}

TEST(RelposeLinear, Eq9RecoversExactPoseAndRejectsCoplanarPoints) {
  const Rigid3d cam0_from_cam1 = VerticalRig();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Eigen::Vector3d> in_cam0, in_cam1, planar0, planar1;
  for (int i = 0; i < 40; ++i) {
    const Eigen::Vector3d p(u(rng), u(rng), u(rng));
    in_cam1.push_back(p);
    in_cam0.push_back(cam0_from_cam1 * p);
    const Eigen::Vector3d q(u(rng), u(rng), 0.5);
    planar1.push_back(q);
    planar0.push_back(cam0_from_cam1 * q);
  }
  const auto estimate = SolveRelativePoseLinear(in_cam0, in_cam1);
  ASSERT_TRUE(estimate.has_value());
  EXPECT_LT((estimate->translation - cam0_from_cam1.translation).norm(), 1e-12);
  EXPECT_LT(RotationErrorDeg(*estimate, cam0_from_cam1), 1e-9);
  EXPECT_FALSE(SolveRelativePoseLinear(planar0, planar1).has_value());
  EXPECT_LT(SpreadEigenRatio(planar1), 1e-12);
  EXPECT_GT(SpreadEigenRatio(in_cam1), 0.1);
}

TEST(RelposeLinear, AverageOfPosesIsTheirMean) {
  const Rigid3d base = VerticalRig();
  const Eigen::Quaterniond small(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitX()));
  const Rigid3d a(base.rotation * small, base.translation + Eigen::Vector3d(0.001, 0, 0));
  const Rigid3d b(base.rotation * small.conjugate(), base.translation - Eigen::Vector3d(0.001, 0, 0));
  const Rigid3d mean = AverageRigidPoses({a, b});
  EXPECT_LT((mean.translation - base.translation).norm(), 1e-12);
  EXPECT_LT(RotationErrorDeg(mean, base), 1e-9);
}

TEST(RelposeCornerOrder, SymmetriesMapTheGridOntoItself) {
  BoardSpec board;
  board.cols = 4;
  board.rows = 4;
  board.square_size_m = 0.03;
  const auto symmetries = BoardGridSymmetries(board);
  ASSERT_EQ(symmetries.size(), 4u);  // identity, half turn, two quarter turns
  const auto points = board.ObjectPoints();
  for (const BoardSymmetry& symmetry : symmetries) {
    for (int id = 0; id < board.NumCorners(); ++id) {
      EXPECT_LT((symmetry.board_from_board * points[id] - points[symmetry.permutation[id]]).norm(),
                1e-12);
    }
  }
  board.cols = 5;
  EXPECT_EQ(BoardGridSymmetries(board).size(), 2u);
}

TEST(RelposeCost, Cam1ResidualIsTheProjectionThroughTheRig) {
  const Scene scene = MakeScene(0.0, 1, 1);
  const Rigid3d cam0_from_board = BoardPose(scene.board, 30.0, 0.7, 10.0, 0.0);
  const Eigen::Vector3d point = scene.board.ObjectPoints()[5];
  const Eigen::Vector2d observed(500.0, 300.0);
  std::unique_ptr<ceres::CostFunction> cost(
      ReprojectionCost::BoardCornerThroughRig(point, observed));
  const auto board_params = cam0_from_board.ToParams();
  const auto rig_params = scene.rig.cam0_from_cam1.ToParams();
  const double* parameters[] = {board_params.data(), rig_params.data(),
                                scene.rig.cam1.intrinsics.params.data()};
  Eigen::Vector2d residual;
  ASSERT_TRUE(cost->Evaluate(parameters, residual.data(), nullptr));
  const auto expected = Project(scene.rig.cam1.intrinsics,
                                scene.rig.cam0_from_cam1.Inverse() * cam0_from_board * point);
  ASSERT_TRUE(expected.has_value());
  EXPECT_LT((residual - (*expected - observed)).norm(), 1e-9);
}

TEST(RelativePose, ExactCornersRecoverTheRig) {
  const Scene scene = MakeScene(0.0, 8, 1);
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 8);
  EXPECT_LT((report.rig.cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation).norm(),
            1e-9);
  EXPECT_LT(RotationErrorDeg(report.rig.cam0_from_cam1, scene.rig.cam0_from_cam1), 1e-7);
  EXPECT_NEAR(report.baseline_m, scene.rig.cam0_from_cam1.translation.norm(), 1e-9);
  EXPECT_LT(report.rms_px, 1e-6);
  // The linear step alone is exact on exact corners too.
  EXPECT_LT((report.linear_cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation)
                .norm(),
            1e-7);
  for (const auto& pair : report.pairs) {
    EXPECT_TRUE(pair.used) << pair.reason;
    EXPECT_EQ(pair.cam1_order, 0);
    EXPECT_EQ(pair.num_corners, scene.board.NumCorners());
  }
}

TEST(RelativePose, HalfTurnedCornerOrdersAreResolved) {
  // 7 x 5 inner corners: 8 x 6 squares, a colouring symmetric under a half turn.
  Scene scene = MakeScene(0.1, 8, 7);
  HalfTurn(scene.board, &scene.pairs[1].cam1);
  HalfTurn(scene.board, &scene.pairs[4].cam1);
  HalfTurn(scene.board, &scene.pairs[6].cam0);  // cam0 flipped alone: cam1 must follow it
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 8);
  EXPECT_EQ(report.pairs[0].cam1_order, 0);
  EXPECT_EQ(report.pairs[1].cam1_order, 1);
  EXPECT_EQ(report.pairs[4].cam1_order, 1);
  EXPECT_EQ(report.pairs[6].cam1_order, 1);
  EXPECT_LT(std::abs(report.baseline_m - scene.rig.cam0_from_cam1.translation.norm()), 5e-4);
  EXPECT_LT(report.rms_px, 0.2);

  RelativePoseOptions trusting;
  trusting.resolve_corner_order = false;
  const RelativePoseReport naive = Estimate(scene, trusting);
  EXPECT_LT(naive.num_pairs_used, 8);  // the flipped pairs disagree and are left out
}

TEST(RelativePose, QuarterTurnsOfSquareBoardsAreResolved) {
  Scene scene = MakeScene(0.0, 6, 9, 6, 6);
  for (int& id : scene.pairs[2].cam1.corner_ids) {
    const int r = id / 6, c = id % 6;
    id = (5 - c) * 6 + r;  // the inverse of a quarter turn
  }
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 6);
  EXPECT_NE(report.pairs[2].cam1_order, 0);
  EXPECT_LT((report.rig.cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation).norm(),
            1e-9);
}

TEST(RelativePose, PairsSeenByOneCameraAreReportedUnused) {
  Scene scene = MakeScene(0.0, 6, 11);
  scene.pairs[2].cam1 = BoardDetection{};
  scene.pairs[2].cam1.reason = "no checkerboard";
  scene.pairs[3].cam0 = BoardDetection{};
  scene.pairs[3].cam0.reason = "too dark";
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 4);
  EXPECT_FALSE(report.pairs[2].used);
  EXPECT_NE(report.pairs[2].reason.find("cam0 only"), std::string::npos) << report.pairs[2].reason;
  EXPECT_NE(report.pairs[2].reason.find("no checkerboard"), std::string::npos);
  EXPECT_NE(report.pairs[3].reason.find("cam1 only"), std::string::npos) << report.pairs[3].reason;
  EXPECT_LT((report.rig.cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation).norm(),
            1e-9);
}

TEST(RelativePose, BoardMovedBetweenExposuresIsLeftOut) {
  Scene scene = MakeScene(0.0, 6, 13);
  // cam1's image of pair 4 shows the board at another pose than cam0's.
  const Rigid3d elsewhere = BoardPose(scene.board, 100.0, 0.9, 30.0, 0.05);
  std::mt19937 rng(1);
  scene.pairs[4].cam1 = Detect(scene.rig.cam1, scene.board,
                               scene.rig.cam0_from_cam1.Inverse() * elsewhere, 0.0, &rng);
  ASSERT_TRUE(scene.pairs[4].cam1.found);
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_FALSE(report.pairs[4].used);
  EXPECT_NE(report.pairs[4].reason.find("disagrees"), std::string::npos);
  EXPECT_LT((report.rig.cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation).norm(),
            1e-9);
}

TEST(RelativePose, SlightlyMovedBoardIsRejectedByTheSynchronisationTest) {
  Scene scene = MakeScene(0.1, 8, 31);
  // Pair 3's board moved by 15 mm and 2 degrees between the two exposures: too little for the
  // consensus test, enough to spoil the joint fit.
  const Rigid3d cam0_from_board = BoardPose(scene.board, 360.0 * 3 / 8, 0.6 + 0.1 * 3,
                                            15.0 + 7.0 * 0, -0.05 + 0.02 * 3);
  const Rigid3d moved(
      Eigen::Quaterniond(Eigen::AngleAxisd(2.0 / kDegPerRad, Eigen::Vector3d::UnitZ())) *
          cam0_from_board.rotation,
      cam0_from_board.translation + Eigen::Vector3d(0.015, 0.0, 0.0));
  std::mt19937 rng(2);
  scene.pairs[3].cam1 =
      Detect(scene.rig.cam1, scene.board, scene.rig.cam0_from_cam1.Inverse() * moved, 0.1, &rng);
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 7);
  EXPECT_FALSE(report.pairs[3].used);
  EXPECT_NE(report.pairs[3].reason.find("not simultaneous"), std::string::npos)
      << report.pairs[3].reason;
  EXPECT_LT(report.rms_px, 0.2);
  EXPECT_LT(std::abs(report.baseline_m - scene.rig.cam0_from_cam1.translation.norm()), 3e-4);
}

// A pair whose board moved a little between the exposures: each camera alone fits it as well
// as any other pair, and its joint RMS stays under twice the others'; the synchronisation test
// still singles it out, and only it.
TEST(RelativePose, MovedBoardIsCaughtByTheSynchronisationTest) {
  Scene scene = MakeScene(0.1, 6, 31);
  const Rigid3d cam0_from_board = BoardPose(scene.board, 360.0 * 3 / 6, 0.6 + 0.1 * 3,
                                            15.0 + 7.0 * 0, -0.05 + 0.02 * 3);
  const Rigid3d moved(cam0_from_board.rotation,
                      cam0_from_board.translation + Eigen::Vector3d(0.0, 0.0045, 0.0));
  std::mt19937 rng(2);
  scene.pairs[3].cam1 =
      Detect(scene.rig.cam1, scene.board, scene.rig.cam0_from_cam1.Inverse() * moved, 0.1, &rng);
  RelativePoseOptions off;
  off.sync_test.false_alarm_rate = 0.0;
  const RelativePoseReport kept = Estimate(scene, off);
  ASSERT_TRUE(kept.success) << kept.message;
  ASSERT_TRUE(kept.pairs[3].used) << kept.pairs[3].reason;
  EXPECT_GT(kept.pairs[3].rms_px, 0.3);
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 5);
  EXPECT_FALSE(report.pairs[3].used);
  EXPECT_NE(report.pairs[3].reason.find("disagree on the board's pose by"), std::string::npos)
      << report.pairs[3].reason;
  EXPECT_LT(report.rms_px, 0.16);
  EXPECT_LT(std::abs(report.baseline_m - scene.rig.cam0_from_cam1.translation.norm()), 3e-4);
  // Exact corners: the noise floor keeps the test from flagging round-off.
  const RelativePoseReport exact = Estimate(MakeScene(0.0, 6, 31));
  EXPECT_EQ(exact.num_pairs_used, 6);
  EXPECT_EQ(exact.sync_test.corner_noise_px[0], RelativePoseOptions().sync_test.min_corner_noise_px);
}

TEST(RelativePose, AllPairsAtOnePoseAreDegenerate) {
  Scene scene = MakeScene(0.2, 1, 17);
  std::mt19937 rng(5);
  const Rigid3d cam0_from_board = BoardPose(scene.board, 40.0, 0.7, 10.0, 0.0);
  scene.pairs.clear();
  for (int i = 0; i < 5; ++i) {
    StereoBoardPair pair;
    pair.name = "same" + std::to_string(i);
    pair.cam0 = Detect(scene.rig.cam0, scene.board, cam0_from_board, 0.2, &rng);
    pair.cam1 = Detect(scene.rig.cam1, scene.board,
                       scene.rig.cam0_from_cam1.Inverse() * cam0_from_board, 0.2, &rng);
    scene.pairs.push_back(pair);
  }
  const RelativePoseReport report = Estimate(scene);
  EXPECT_FALSE(report.success);
  EXPECT_TRUE(report.degenerate);
  EXPECT_NE(report.message.find("degenerate"), std::string::npos) << report.message;
}

TEST(RelativePose, TooFewPairsFailWithEachReason) {
  Scene scene = MakeScene(0.0, 3, 19);
  scene.pairs[0].cam1 = BoardDetection{};
  scene.pairs[0].cam1.reason = "blurred";
  scene.pairs[1].cam0 = BoardDetection{};
  scene.pairs[1].cam0.reason = "occluded";
  const RelativePoseReport report = Estimate(scene);
  EXPECT_FALSE(report.success);
  EXPECT_NE(report.message.find("too few usable pairs"), std::string::npos) << report.message;
  EXPECT_NE(report.message.find("blurred"), std::string::npos) << report.message;
  EXPECT_NE(report.message.find("occluded"), std::string::npos) << report.message;
}

TEST(RelativePose, RefiningIntrinsicsRecoversPerturbedCameras) {
  const Scene scene = MakeScene(0.0, 10, 23);
  CameraModel cam0 = scene.rig.cam0, cam1 = scene.rig.cam1;
  cam0.intrinsics.u0() += 1.5;
  cam1.intrinsics.gamma_v() *= 1.003;
  RelativePoseOptions options;
  options.refine_intrinsics = true;
  const RelativePoseReport report =
      EstimateRelativePose(cam0, cam1, scene.board, scene.pairs, options);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_LT(report.rms_px, 1e-4);
  EXPECT_LT((report.rig.cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation).norm(),
            1e-5);
  EXPECT_NEAR(report.rig.cam0.intrinsics.u0(), scene.rig.cam0.intrinsics.u0(), 1e-2);
}

TEST(RelativePose, FixedIntrinsicsKeepTheirValues) {
  const Scene scene = MakeScene(0.0, 5, 23);
  CameraModel cam0 = scene.rig.cam0, cam1 = scene.rig.cam1;
  cam0.intrinsics.u0() += 1.5;
  cam0.intrinsics.gamma_v() *= 1.003;
  cam0.intrinsics.params[UnifiedIntrinsics::kK5] = 1e-4;
  RelativePoseOptions options;
  options.refine_intrinsics = true;
  const RelativePoseReport by_default =
      EstimateRelativePose(cam0, cam1, scene.board, scene.pairs, options);
  ASSERT_TRUE(by_default.success) << by_default.message;
  EXPECT_EQ(by_default.rig.cam0.intrinsics.params[UnifiedIntrinsics::kK5], 1e-4);
  EXPECT_EQ(by_default.rig.cam0.intrinsics.params[UnifiedIntrinsics::kAlpha], 0.0);
  EXPECT_NE(by_default.rig.cam0.intrinsics.u0(), cam0.intrinsics.u0());
  options.fixed_intrinsics.fill(true);
  options.fixed_intrinsics[UnifiedIntrinsics::kU0] = false;
  const RelativePoseReport only_u0 =
      EstimateRelativePose(cam0, cam1, scene.board, scene.pairs, options);
  ASSERT_TRUE(only_u0.success) << only_u0.message;
  EXPECT_EQ(only_u0.rig.cam0.intrinsics.gamma_v(), cam0.intrinsics.gamma_v());
  for (int p = 0; p < UnifiedIntrinsics::kNumParams; ++p) {
    if (p == UnifiedIntrinsics::kU0) continue;  // free in both cameras
    EXPECT_EQ(only_u0.rig.cam1.intrinsics.params[p], cam1.intrinsics.params[p]) << p;
  }
  EXPECT_NE(only_u0.rig.cam0.intrinsics.u0(), cam0.intrinsics.u0());
}

TEST(RelativePose, Cam1CanHoldADifferentFixedSet) {
  const Scene scene = MakeScene(0.0, 5, 23);
  CameraModel cam0 = scene.rig.cam0, cam1 = scene.rig.cam1;
  cam0.intrinsics.u0() += 1.0;
  cam1.intrinsics.u0() += 1.0;
  RelativePoseOptions options;
  options.refine_intrinsics = true;
  options.cam1_fixed_intrinsics = DefaultFixedIntrinsics();
  (*options.cam1_fixed_intrinsics)[UnifiedIntrinsics::kU0] = true;
  const RelativePoseReport report =
      EstimateRelativePose(cam0, cam1, scene.board, scene.pairs, options);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.rig.cam1.intrinsics.u0(), cam1.intrinsics.u0());
  EXPECT_NE(report.rig.cam0.intrinsics.u0(), cam0.intrinsics.u0());
}

TEST(RelativePose, InvalidOptionsAndCancellationThrow) {
  const Scene scene = MakeScene(0.0, 4, 29);
  RelativePoseOptions options;
  options.huber_loss_px = -1.0;
  EXPECT_THROW(Estimate(scene, options), InvalidArgument);
  options = RelativePoseOptions();
  options.sync_test.false_alarm_rate = 1.5;
  EXPECT_THROW(Estimate(scene, options), InvalidArgument);
  ProgressSink cancelled;
  cancelled.is_cancelled = [] { return true; };
  EXPECT_THROW(EstimateRelativePose(scene.rig.cam0, scene.rig.cam1, scene.board, scene.pairs, {},
                                    cancelled),
               Cancelled);
}

}  // namespace
}  // namespace omnirig
