// The rig refinement's hand-written Jacobians against the autodiff functors they replace.

#include "engine/stereo/relpose_cost.h"

#include <array>
#include <cmath>
#include <memory>
#include <random>

#include <gtest/gtest.h>

namespace omnirig {
namespace {

using Intrinsics = std::array<double, UnifiedIntrinsics::kNumParams>;
using Pose = std::array<double, 7>;
using PoseJacobian = Eigen::Matrix<double, 2, 7, Eigen::RowMajor>;
using IntrinsicsJacobian = Eigen::Matrix<double, 2, UnifiedIntrinsics::kNumParams, Eigen::RowMajor>;

struct RandomRig {
  explicit RandomRig(unsigned seed) : rng(seed) {}
  double Unit() { return std::uniform_real_distribution<double>(-1.0, 1.0)(rng); }
  Intrinsics Camera() {
    return {0.8 + 0.4 * Unit(), 300 + 20 * Unit(), 290 + 20 * Unit(), 480 + 5 * Unit(),
            300 + 5 * Unit(),   0.01 * Unit(),     -0.2 + 0.05 * Unit(), 0.04 * Unit(),
            0.003 * Unit(),     0.003 * Unit(),    0.01 * Unit()};
  }
  // A unit quaternion `spread` away from the identity (Eigen order x, y, z, w) and a translation.
  Pose Rigid(double spread, double translation) {
    const Eigen::Quaterniond q =
        Eigen::Quaterniond(1.0, spread * Unit(), spread * Unit(), spread * Unit()).normalized();
    return {q.x(), q.y(), q.z(), q.w(), translation * Unit(), translation * Unit(),
            translation * Unit()};
  }
  std::mt19937 rng;
};

// Boards 0.3-0.9 m in front of cam0 at any tilt, rigs with a ~0.1 m baseline and any small
// rotation: residuals and all three Jacobians agree, and so with any block's Jacobian left out.
TEST(RigCam1CornerAnalyticCost, MatchesTheJets) {
  RandomRig random(7);
  int compared = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const Intrinsics intrinsics = random.Camera();
    Pose board = random.Rigid(1.0, 0.2);
    board[6] = 0.6 + 0.3 * random.Unit();
    const Pose rig = random.Rigid(0.2, 0.1);
    const Eigen::Vector3d point(0.2 * random.Unit(), 0.15 * random.Unit(), 0.0);
    const Eigen::Vector2d observed(480 + 200 * random.Unit(), 300 + 200 * random.Unit());
    const RigCam1CornerAnalyticCost analytic(observed, point);
    const std::unique_ptr<ceres::CostFunction> jets(RigCam1CornerCost::Create(observed, point));
    const double* parameters[3] = {board.data(), rig.data(), intrinsics.data()};
    double residual_a[2], residual_j[2];
    PoseJacobian board_a, board_j, rig_a, rig_j;
    IntrinsicsJacobian intrinsics_a, intrinsics_j;
    double* jacobians_a[3] = {board_a.data(), rig_a.data(), intrinsics_a.data()};
    double* jacobians_j[3] = {board_j.data(), rig_j.data(), intrinsics_j.data()};
    const bool valid = jets->Evaluate(parameters, residual_j, jacobians_j);
    ASSERT_EQ(analytic.Evaluate(parameters, residual_a, jacobians_a), valid) << trial;
    if (!valid) continue;
    ++compared;
    // The same operations (up to the compiler's order and fused multiply-adds): the residual
    // and the Jacobians agree to round-off.
    EXPECT_NEAR(residual_a[0], residual_j[0], 1e-12 * (1.0 + std::abs(residual_j[0]))) << trial;
    EXPECT_NEAR(residual_a[1], residual_j[1], 1e-12 * (1.0 + std::abs(residual_j[1]))) << trial;
    EXPECT_LT((board_a - board_j).norm(), 1e-9 * (1.0 + board_j.norm())) << trial;
    EXPECT_LT((rig_a - rig_j).norm(), 1e-9 * (1.0 + rig_j.norm())) << trial;
    EXPECT_LT((intrinsics_a - intrinsics_j).norm(), 1e-9 * (1.0 + intrinsics_j.norm())) << trial;
    // Constant blocks (Ceres passes null): each Jacobian alone, and none.
    for (int block = 0; block < 3; ++block) {
      PoseJacobian pose_only;
      IntrinsicsJacobian intrinsics_only;
      double* one[3] = {nullptr, nullptr, nullptr};
      one[block] = block == 2 ? intrinsics_only.data() : pose_only.data();
      double residual[2];
      ASSERT_TRUE(analytic.Evaluate(parameters, residual, one));
      EXPECT_EQ(residual[0], residual_a[0]);
      if (block < 2) {
        EXPECT_TRUE(pose_only == (block == 0 ? board_a : rig_a)) << trial << " block " << block;
      } else {
        EXPECT_TRUE(intrinsics_only == intrinsics_a) << trial;
      }
    }
    double residual[2];
    ASSERT_TRUE(analytic.Evaluate(parameters, residual, nullptr));
    EXPECT_EQ(residual[1], residual_a[1]);
  }
  EXPECT_GT(compared, 250);
}

// A point behind the mirror's valid domain is refused as by the Jets (not silently projected).
TEST(RigCam1CornerAnalyticCost, RefusesWhereTheJetsRefuse) {
  const Intrinsics intrinsics = {0.9, 300, 300, 480, 300, 0, -0.2, 0.04, 0, 0, 0};
  const Pose board = {0, 0, 0, 1, 0, 0, -1.0};  // the board 1 m behind cam0...
  const Pose rig = {0, 0, 0, 1, 0.1, 0, 0};     // ...and behind cam1
  const Eigen::Vector3d point(0.05, 0.05, 0.0);
  const RigCam1CornerAnalyticCost analytic(Eigen::Vector2d(480, 300), point);
  const std::unique_ptr<ceres::CostFunction> jets(
      RigCam1CornerCost::Create(Eigen::Vector2d(480, 300), point));
  const double* parameters[3] = {board.data(), rig.data(), intrinsics.data()};
  double residual[2];
  EXPECT_FALSE(jets->Evaluate(parameters, residual, nullptr));
  EXPECT_FALSE(analytic.Evaluate(parameters, residual, nullptr));
}

// cam0's corners use the calibration's BoardCornerAnalyticCost (intrinsics block first): the
// same residual and Jacobians as the rig's autodiff functor for cam0.
TEST(RigCam0Corner, CalibrationCostMatchesTheRigFunctor) {
  RandomRig random(8);
  int compared = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const Intrinsics intrinsics = random.Camera();
    Pose board = random.Rigid(1.0, 0.2);
    board[6] = 0.6 + 0.3 * random.Unit();
    const Eigen::Vector3d point(0.2 * random.Unit(), 0.15 * random.Unit(), 0.0);
    const Eigen::Vector2d observed(480 + 200 * random.Unit(), 300 + 200 * random.Unit());
    const BoardCornerAnalyticCost analytic(point, observed);
    const std::unique_ptr<ceres::CostFunction> jets(RigCam0CornerCost::Create(observed, point));
    const double* parameters_a[2] = {intrinsics.data(), board.data()};
    const double* parameters_j[2] = {board.data(), intrinsics.data()};
    double residual_a[2], residual_j[2];
    PoseJacobian board_a, board_j;
    IntrinsicsJacobian intrinsics_a, intrinsics_j;
    double* jacobians_a[2] = {intrinsics_a.data(), board_a.data()};
    double* jacobians_j[2] = {board_j.data(), intrinsics_j.data()};
    const bool valid = jets->Evaluate(parameters_j, residual_j, jacobians_j);
    ASSERT_EQ(analytic.Evaluate(parameters_a, residual_a, jacobians_a), valid) << trial;
    if (!valid) continue;
    ++compared;
    EXPECT_NEAR(residual_a[0], residual_j[0], 1e-12 * (1.0 + std::abs(residual_j[0]))) << trial;
    EXPECT_NEAR(residual_a[1], residual_j[1], 1e-12 * (1.0 + std::abs(residual_j[1]))) << trial;
    EXPECT_LT((board_a - board_j).norm(), 1e-9 * (1.0 + board_j.norm())) << trial;
    EXPECT_LT((intrinsics_a - intrinsics_j).norm(), 1e-9 * (1.0 + intrinsics_j.norm())) << trial;
  }
  EXPECT_GT(compared, 150);
}

}  // namespace
}  // namespace omnirig
