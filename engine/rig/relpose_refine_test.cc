// The joint refinement of the stereo rig (relpose_refine.h) on its own: the pairs' corners are
// given directly (cam1's ids already consistent), without the pipeline of relative_pose.h.

#include "engine/rig/relpose_refine.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "testing/rig/relpose_test_scene.h"

namespace omnirig {
namespace {

using namespace relpose_test;  // NOLINT: the shared test scenes

// The corners of pair i of `scene` as the refinement takes them (every corner in both images).
RigPairCorners CornersOf(const Scene& scene, int i) {
  const std::vector<Eigen::Vector3d> object_points = scene.board.ObjectPoints();
  RigPairCorners corners;
  const StereoBoardPair& pair = scene.pairs[i];
  for (size_t c = 0; c < pair.cam0.corner_ids.size(); ++c) {
    corners.points_in_board0.push_back(object_points[pair.cam0.corner_ids[c]]);
    corners.pixels0.push_back(pair.cam0.corners_px[c]);
  }
  for (size_t c = 0; c < pair.cam1.corner_ids.size(); ++c) {
    corners.points_in_board1.push_back(object_points[pair.cam1.corner_ids[c]]);
    corners.pixels1.push_back(pair.cam1.corners_px[c]);
  }
  return corners;
}

struct Problem {
  Scene scene;
  std::vector<RigPairCorners> pairs;
  std::vector<Rigid3d> true_cam0_from_board;
};

Problem MakeProblem(double noise_px, int num_pairs, unsigned seed) {
  Problem problem;
  problem.scene = MakeScene(noise_px, num_pairs, seed);
  for (int i = 0; i < num_pairs; ++i) {
    problem.pairs.push_back(CornersOf(problem.scene, i));
    problem.true_cam0_from_board.push_back(PairBoardPose(problem.scene.board, i, num_pairs));
  }
  return problem;
}

// A pose moved by a small rotation (about a fixed axis) and translation.
Rigid3d Perturbed(const Rigid3d& pose, double angle_deg, const Eigen::Vector3d& shift_m) {
  const Eigen::Quaterniond turn(
      Eigen::AngleAxisd(angle_deg / kDegPerRad, Eigen::Vector3d(0.2, 1.0, -0.4).normalized()));
  return Rigid3d(turn * pose.rotation, pose.translation + shift_m);
}

TEST(RigRefinement, DefaultFixedIntrinsicsAreSkewAndK5) {
  const auto fixed = DefaultFixedIntrinsics();
  for (int p = 0; p < UnifiedIntrinsics::kNumParams; ++p) {
    EXPECT_EQ(fixed[p], p == UnifiedIntrinsics::kAlpha || p == UnifiedIntrinsics::kK5) << p;
  }
}

TEST(RigRefinement, BoardCentreIsTheMeanOfBothCamerasObjectPoints) {
  RigPairCorners pair;
  EXPECT_EQ(RigPairBoardCentre(pair), Eigen::Vector3d::Zero());
  pair.points_in_board0 = {Eigen::Vector3d(0.0, 0.0, 0.0), Eigen::Vector3d(0.3, 0.0, 0.0)};
  pair.points_in_board1 = {Eigen::Vector3d(0.0, 0.6, 0.0)};
  EXPECT_TRUE(RigPairBoardCentre(pair).isApprox(Eigen::Vector3d(0.1, 0.2, 0.0), 1e-15));
}

// Exact corners, every pose started off the truth (2 deg, 1-2 cm): the solution is the truth,
// the residuals vanish and so does the covariance's scale.
TEST(RigRefinement, ExactCornersConvergeToTheTruthFromAPerturbedStart) {
  const Problem problem = MakeProblem(0.0, 8, 1);
  StereoRig rig = problem.scene.rig;
  rig.cam0_from_cam1 = Perturbed(rig.cam0_from_cam1, 2.0, Eigen::Vector3d(0.01, -0.02, 0.01));
  std::vector<Rigid3d> cam0_from_board;
  for (const Rigid3d& pose : problem.true_cam0_from_board) {
    cam0_from_board.push_back(Perturbed(pose, 2.0, Eigen::Vector3d(-0.01, 0.01, 0.02)));
  }
  RigUncertainty uncertainty;
  const SolverSummary summary =
      RefineRig(problem.pairs, RigRefinementOptions(), &rig, &cam0_from_board, &uncertainty);
  ASSERT_TRUE(summary.usable) << summary.termination;
  EXPECT_LT(summary.final_cost, 1e-12 * summary.initial_cost);
  const Rigid3d& truth = problem.scene.rig.cam0_from_cam1;
  EXPECT_LT((rig.cam0_from_cam1.translation - truth.translation).norm(), 1e-9);
  EXPECT_LT(RotationErrorDeg(rig.cam0_from_cam1, truth), 1e-7);
  for (size_t i = 0; i < cam0_from_board.size(); ++i) {
    EXPECT_LT((cam0_from_board[i].translation - problem.true_cam0_from_board[i].translation).norm(),
              1e-9);
    EXPECT_LT(PairRmsPx(rig, cam0_from_board[i], problem.pairs[i]), 1e-6);
  }
  ASSERT_TRUE(uncertainty.valid);
  EXPECT_LT(uncertainty.baseline_std_m, 1e-9);
}

// Noisy corners: the rig lands within a few of its own standard deviations of the truth, and
// the uncertainty evaluated again at the solution is the one the solve reported.
TEST(RigRefinement, UncertaintyCoversTheErrorAndIsReproducedAtTheSolution) {
  const double noise_px = 0.2;
  const Problem problem = MakeProblem(noise_px, 12, 2);
  StereoRig rig = problem.scene.rig;
  std::vector<Rigid3d> cam0_from_board = problem.true_cam0_from_board;
  RigUncertainty uncertainty;
  RigRefinementOptions options;
  options.huber_loss_px = 0.0;  // plain least squares: the covariance's own assumptions
  ASSERT_TRUE(RefineRig(problem.pairs, options, &rig, &cam0_from_board, &uncertainty).usable);
  ASSERT_TRUE(uncertainty.valid);
  ASSERT_TRUE(uncertainty.robust_valid);
  const Eigen::Vector3d error =
      rig.cam0_from_cam1.translation - problem.scene.rig.cam0_from_cam1.translation;
  for (int a = 0; a < 3; ++a) {
    EXPECT_GT(uncertainty.translation_std_m[a], 0.0);
    EXPECT_LT(std::abs(error[a]), 4.0 * uncertainty.translation_std_m[a]) << a;
  }
  EXPECT_LT(RotationErrorDeg(rig.cam0_from_cam1, problem.scene.rig.cam0_from_cam1),
            4.0 * uncertainty.rotation_std_deg);
  // Independent corner noise: the cluster-robust std agrees with the covariance's in order.
  EXPECT_GT(uncertainty.robust_baseline_std_m, 0.3 * uncertainty.baseline_std_m);
  EXPECT_LT(uncertainty.robust_baseline_std_m, 3.0 * uncertainty.baseline_std_m);
  const RigUncertainty again = EstimateRigUncertainty(problem.pairs, options, rig, cam0_from_board);
  ASSERT_TRUE(again.valid);
  EXPECT_NEAR(again.baseline_std_m, uncertainty.baseline_std_m, 1e-6 * uncertainty.baseline_std_m);
  EXPECT_NEAR(again.robust_baseline_std_m, uncertainty.robust_baseline_std_m,
              1e-6 * uncertainty.robust_baseline_std_m);
}

// With refine_intrinsics, the terms of the fixed set keep their values and the others move
// back towards the truth from a perturbed start; cam1_fixed_intrinsics applies to cam1 alone.
TEST(RigRefinement, IntrinsicsRefineExceptTheFixedSet) {
  const Problem problem = MakeProblem(0.0, 12, 3);
  StereoRig rig = problem.scene.rig;
  rig.cam0.intrinsics.params[UnifiedIntrinsics::kAlpha] = 1e-4;  // fixed: must stay
  rig.cam0.intrinsics.params[3] += 2.0;                            // u0, free
  rig.cam1.intrinsics.params[3] += 2.0;                            // u0, fixed in cam1 only
  std::vector<Rigid3d> cam0_from_board = problem.true_cam0_from_board;
  RigRefinementOptions options;
  options.refine_intrinsics = true;
  auto cam1_fixed = DefaultFixedIntrinsics();
  cam1_fixed[3] = true;
  options.cam1_fixed_intrinsics = cam1_fixed;
  ASSERT_TRUE(RefineRig(problem.pairs, options, &rig, &cam0_from_board, nullptr).usable);
  EXPECT_EQ(rig.cam0.intrinsics.params[UnifiedIntrinsics::kAlpha], 1e-4);
  EXPECT_EQ(rig.cam0.intrinsics.params[UnifiedIntrinsics::kK5], 0.0);
  EXPECT_EQ(rig.cam1.intrinsics.params[3], problem.scene.rig.cam1.intrinsics.params[3] + 2.0);
  // cam0's u0 moved from its perturbed start (cam1's held u0 and cam0's skew stay wrong, so
  // the fit cannot return to the exact truth).
  EXPECT_NE(rig.cam0.intrinsics.params[3], problem.scene.rig.cam0.intrinsics.params[3] + 2.0);

  // Without refine_intrinsics, nothing of the cameras moves.
  StereoRig fixed_rig = problem.scene.rig;
  fixed_rig.cam0.intrinsics.params[3] += 2.0;
  cam0_from_board = problem.true_cam0_from_board;
  ASSERT_TRUE(
      RefineRig(problem.pairs, RigRefinementOptions(), &fixed_rig, &cam0_from_board, nullptr)
          .usable);
  EXPECT_EQ(fixed_rig.cam0.intrinsics.params[3], problem.scene.rig.cam0.intrinsics.params[3] + 2.0);
}

TEST(RigRefinement, CancellationThrows) {
  const Problem problem = MakeProblem(0.1, 6, 4);
  StereoRig rig = problem.scene.rig;
  rig.cam0_from_cam1 = Perturbed(rig.cam0_from_cam1, 1.0, Eigen::Vector3d(0.01, 0.0, 0.0));
  std::vector<Rigid3d> cam0_from_board = problem.true_cam0_from_board;
  ProgressSink progress;
  progress.is_cancelled = [] { return true; };
  EXPECT_THROW(
      RefineRig(problem.pairs, RigRefinementOptions(), &rig, &cam0_from_board, nullptr, progress),
      Cancelled);
  std::vector<Rigid3d> too_few(2);
  EXPECT_THROW(RefineRig(problem.pairs, RigRefinementOptions(), &rig, &too_few, nullptr),
               InvalidArgument);
}

// One board pose through a fixed rig: exact corners give the true pose and a zero sum; with
// noise, the whitened sum scales as 1 / noise_px^2 and averages its degrees of freedom.
TEST(RigRefinement, BoardThroughRigIsWeightedLeastSquares) {
  const Problem exact = MakeProblem(0.0, 4, 5);
  Rigid3d pose = Perturbed(exact.true_cam0_from_board[0], 1.0, Eigen::Vector3d(0.005, 0.0, 0.0));
  EXPECT_LT(FitBoardThroughRig(exact.scene.rig, exact.pairs[0], {0.1, 0.1}, &pose), 1e-12);
  EXPECT_LT((pose.translation - exact.true_cam0_from_board[0].translation).norm(), 1e-9);
  EXPECT_THROW(FitBoardThroughRig(exact.scene.rig, exact.pairs[0], {0.0, 0.1}, &pose),
               InvalidArgument);

  const double noise_px = 0.15;
  const Problem noisy = MakeProblem(noise_px, 40, 6);
  double sum = 0.0, dof = 0.0;
  for (size_t i = 0; i < noisy.pairs.size(); ++i) {
    Rigid3d fitted = noisy.true_cam0_from_board[i];
    const double whitened =
        FitBoardThroughRig(noisy.scene.rig, noisy.pairs[i], {noise_px, noise_px}, &fitted);
    ASSERT_GE(whitened, 0.0);
    Rigid3d refitted = noisy.true_cam0_from_board[i];
    const double halved = FitBoardThroughRig(noisy.scene.rig, noisy.pairs[i],
                                             {2.0 * noise_px, 2.0 * noise_px}, &refitted);
    EXPECT_NEAR(halved, 0.25 * whitened, 1e-6 * whitened);
    sum += whitened;
    dof += 2.0 * (noisy.pairs[i].pixels0.size() + noisy.pairs[i].pixels1.size()) - 6.0;
  }
  // chi^2 over 40 pairs of ~134 dof each: the mean is within a few percent of the dof.
  EXPECT_NEAR(sum / dof, 1.0, 0.05);
}

// The pair RMS counts a corner that does not project as 1e3 px instead of dropping it.
TEST(RigRefinement, PairRmsCountsCornersThatDoNotProject) {
  const Problem problem = MakeProblem(0.0, 4, 7);
  RigPairCorners pair = problem.pairs[0];
  EXPECT_LT(PairRmsPx(problem.scene.rig, problem.true_cam0_from_board[0], pair), 1e-6);
  const size_t n = pair.pixels0.size() + pair.pixels1.size() + 1;
  // A point straight up cam0's -z axis (towards the mirror): outside the model's domain.
  pair.points_in_board0.push_back(problem.true_cam0_from_board[0].Inverse() *
                                  Eigen::Vector3d(0.0, 0.0, -10.0));
  pair.pixels0.push_back(Eigen::Vector2d(500.0, 400.0));
  const double rms = PairRmsPx(problem.scene.rig, problem.true_cam0_from_board[0], pair);
  EXPECT_NEAR(rms, std::sqrt(1e6 / n), 1e-3);
}

}  // namespace
}  // namespace omnirig
