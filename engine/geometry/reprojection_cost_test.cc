// The reprojection cost family: every layout's residual against the projection it stands for,
// and its hand-written Jacobians against numeric differences (ceres::GradientChecker), also at
// non-unit quaternions, and with blocks held constant.

#include "engine/geometry/reprojection_cost.h"

#include <array>
#include <cmath>
#include <memory>
#include <optional>
#include <random>
#include <vector>

#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

namespace omnirig {
namespace {

using Pose = std::array<double, 7>;

struct Random {
  explicit Random(unsigned seed) : rng(seed) {}
  double Unit() { return std::uniform_real_distribution<double>(-1.0, 1.0)(rng); }
  // Every intrinsic (skew, tangential, k5 included) away from zero.
  UnifiedIntrinsics Camera() {
    UnifiedIntrinsics camera;
    camera.params = {0.8 + 0.4 * Unit(), 300 + 20 * Unit(),    290 + 20 * Unit(),
                     480 + 5 * Unit(),   300 + 5 * Unit(),     0.01 * Unit(),
                     -0.2 + 0.05 * Unit(), 0.04 * Unit(),      0.003 * Unit(),
                     0.003 * Unit(),     0.01 * Unit()};
    return camera;
  }
  // A quaternion `spread` away from the identity, unit or (with `unit` false) scaled by up to
  // 1.5: the Jacobians differentiate Eigen's q * v, which Jets and numeric differences see off
  // the sphere too.
  Pose Rigid(double spread, double translation, bool unit = true) {
    Eigen::Quaterniond q =
        Eigen::Quaterniond(1.0, spread * Unit(), spread * Unit(), spread * Unit()).normalized();
    if (!unit) q.coeffs() *= 1.0 + 0.5 * Unit();
    return {q.x(), q.y(), q.z(), q.w(), translation * Unit(), translation * Unit(),
            translation * Unit()};
  }
  std::mt19937 rng;
};

Rigid3d FromPose(const Pose& pose) {
  const Eigen::Quaterniond q(pose[3], pose[0], pose[1], pose[2]);
  return Rigid3d(q, Eigen::Vector3d(pose[4], pose[5], pose[6]));
}

// Probes the cost's Jacobians at `parameters` against Ridders' differences (from a step of 1e-4
// of each parameter: the checker's default 1e-2 steps far across the rim's curvature); returns
// whether the point projected. Each block's Jacobian must agree to 1e-7 of its norm (entry by
// entry, the checker's relative test fails on entries near zero, where the differences are
// round-off).
bool JacobiansMatchNumeric(const ceres::CostFunction& cost,
                           const std::vector<const double*>& parameters) {
  const std::vector<const ceres::Manifold*> ambient(parameters.size(), nullptr);
  ceres::NumericDiffOptions numeric_options;
  numeric_options.ridders_relative_initial_step_size = 1e-4;
  ceres::GradientChecker checker(&cost, &ambient, numeric_options);
  ceres::GradientChecker::ProbeResults results;
  double residuals[2];
  if (!cost.Evaluate(parameters.data(), residuals, nullptr)) return false;
  checker.Probe(parameters.data(), 1e-7, &results);  // its verdict is per entry, see above
  EXPECT_TRUE(results.return_value) << results.error_log;
  for (size_t b = 0; b < parameters.size(); ++b) {
    const ceres::Matrix& analytic = results.jacobians[b];
    const ceres::Matrix& numeric = results.numeric_jacobians[b];
    EXPECT_LT((analytic - numeric).norm(), 1e-7 * (1.0 + numeric.norm()))
        << "block " << b << "\n" << results.error_log;
  }
  return true;
}

// Evaluates with one block's Jacobian only (the others constant) and compares with all.
void ConstantBlocksChangeNothing(const ceres::CostFunction& cost,
                                 const std::vector<const double*>& parameters) {
  const std::vector<int32_t>& sizes = cost.parameter_block_sizes();
  std::vector<std::vector<double>> all(sizes.size());
  std::vector<double*> all_pointers;
  for (size_t b = 0; b < sizes.size(); ++b) {
    all[b].assign(2 * sizes[b], 0.0);
    all_pointers.push_back(all[b].data());
  }
  double residuals[2], again[2];
  ASSERT_TRUE(cost.Evaluate(parameters.data(), residuals, all_pointers.data()));
  for (size_t b = 0; b < sizes.size(); ++b) {
    std::vector<double> one_block(2 * sizes[b], 0.0);
    std::vector<double*> pointers(sizes.size(), nullptr);
    pointers[b] = one_block.data();
    ASSERT_TRUE(cost.Evaluate(parameters.data(), again, pointers.data()));
    EXPECT_EQ(again[0], residuals[0]);
    EXPECT_EQ(one_block, all[b]) << "block " << b;
  }
}

// One trial of a cost: false when the point does not project; else checks the residual against
// `expected_px` - `measured` (when `expected_px` is given: trials at unit quaternions), the
// Jacobians and, with `constant_blocks`, that blocks held constant change nothing.
bool CheckTrial(const ceres::CostFunction& cost, const std::vector<const double*>& parameters,
                const Eigen::Vector2d& measured, const std::optional<Eigen::Vector2d>& expected_px,
                bool check_expected, bool constant_blocks = true) {
  Eigen::Vector2d residual;
  if (!cost.Evaluate(parameters.data(), residual.data(), nullptr)) return false;
  if (check_expected) {
    EXPECT_TRUE(expected_px.has_value());
    if (expected_px) {
      EXPECT_LT((residual - (*expected_px - measured)).norm(), 1e-7);
    }
  }
  EXPECT_TRUE(JacobiansMatchNumeric(cost, parameters));
  if (constant_blocks) ConstantBlocksChangeNothing(cost, parameters);
  return true;
}

TEST(ReprojectionCost, BoardCorner) {
  Random random(11);
  int checked = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const UnifiedIntrinsics camera = random.Camera();
    Pose board = random.Rigid(1.0, 0.2, trial % 2 == 0);
    board[6] = 0.6 + 0.3 * random.Unit();
    const Eigen::Vector3d point(0.2 * random.Unit(), 0.15 * random.Unit(), 0.0);
    const Eigen::Vector2d measured(480 + 200 * random.Unit(), 300 + 200 * random.Unit());
    const std::unique_ptr<ceres::CostFunction> cost(ReprojectionCost::BoardCorner(point, measured));
    const std::vector<const double*> parameters = {board.data(), camera.params.data()};
    const Eigen::Quaterniond q(board[3], board[0], board[1], board[2]);
    const auto expected =
        Project(camera, q * point + Eigen::Vector3d(board[4], board[5], board[6]));
    if (CheckTrial(*cost, parameters, measured, expected, true)) ++checked;
  }
  EXPECT_GT(checked, 80);
}

TEST(ReprojectionCost, BoardCornerThroughRig) {
  Random random(7);
  int checked = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const UnifiedIntrinsics camera = random.Camera();
    Pose board = random.Rigid(1.0, 0.2, trial % 2 == 0);
    board[6] = 0.6 + 0.3 * random.Unit();
    const Pose rig = random.Rigid(0.2, 0.1, trial % 3 == 0);
    const Eigen::Vector3d point(0.2 * random.Unit(), 0.15 * random.Unit(), 0.0);
    const Eigen::Vector2d measured(480 + 200 * random.Unit(), 300 + 200 * random.Unit());
    const std::unique_ptr<ceres::CostFunction> cost(
        ReprojectionCost::BoardCornerThroughRig(point, measured));
    const std::vector<const double*> parameters = {board.data(), rig.data(),
                                                   camera.params.data()};
    const auto expected = Project(camera, FromPose(rig).Inverse() * (FromPose(board) * point));
    if (CheckTrial(*cost, parameters, measured, expected, trial % 2 == 0 && trial % 3 == 0)) {
      ++checked;
    }
  }
  EXPECT_GT(checked, 80);
}

TEST(ReprojectionCost, BoardCornerFixedCamera) {
  Random random(8);
  int checked = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const UnifiedIntrinsics camera = random.Camera();
    Pose board = random.Rigid(1.0, 0.2, trial % 2 == 0);
    board[6] = 0.6 + 0.3 * random.Unit();
    const Rigid3d cam_from_cam0 = FromPose(random.Rigid(0.2, 0.1));
    const Eigen::Vector3d point(0.2 * random.Unit(), 0.15 * random.Unit(), 0.0);
    const Eigen::Vector2d measured(480 + 200 * random.Unit(), 300 + 200 * random.Unit());
    const std::unique_ptr<ceres::CostFunction> cost(
        ReprojectionCost::BoardCornerFixedCamera(point, measured, cam_from_cam0, camera));
    const std::vector<const double*> parameters = {board.data()};
    const auto expected = Project(camera, cam_from_cam0 * (FromPose(board) * point));
    if (CheckTrial(*cost, parameters, measured, expected, trial % 2 == 0, false)) ++checked;
  }
  EXPECT_GT(checked, 80);
}

TEST(ReprojectionCost, Landmark) {
  Random random(3);
  int checked = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const UnifiedIntrinsics camera = random.Camera();
    const Pose rig_from_world = random.Rigid(1.0, 1.0, trial % 2 == 0);
    const Rigid3d cam_from_rig = trial % 3 == 0 ? Rigid3d() : FromPose(random.Rigid(0.1, 0.1));
    const std::array<double, 3> point = {2 * random.Unit(), 2 * random.Unit(),
                                         1 + random.Unit()};
    const Eigen::Vector2d measured(480 + 100 * random.Unit(), 300 + 100 * random.Unit());
    const std::unique_ptr<ceres::CostFunction> cost(
        ReprojectionCost::Landmark(measured, cam_from_rig, camera));
    const std::vector<const double*> parameters = {rig_from_world.data(), point.data()};
    const auto expected = Project(
        camera,
        cam_from_rig * (FromPose(rig_from_world) * Eigen::Vector3d(point[0], point[1], point[2])));
    if (CheckTrial(*cost, parameters, measured, expected, trial % 2 == 0)) ++checked;
  }
  EXPECT_GT(checked, 30);
}

TEST(ReprojectionCost, LandmarkWithCalibration) {
  Random random(5);
  int checked = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const int camera = trial % 2;
    UnifiedIntrinsics intrinsics = random.Camera();
    const Pose rig_from_world = random.Rigid(1.0, 1.0, trial % 4 < 2);
    const Pose cam0_from_cam1 = random.Rigid(0.1, 0.1, trial % 3 == 0);
    const std::array<double, 3> point = {2 * random.Unit(), 2 * random.Unit(),
                                         1 + random.Unit()};
    const Eigen::Vector2d measured(480 + 100 * random.Unit(), 300 + 100 * random.Unit());
    const std::unique_ptr<ceres::CostFunction> cost(
        ReprojectionCost::LandmarkWithCalibration(camera, measured));
    std::vector<const double*> parameters = {rig_from_world.data(), point.data()};
    const std::array<double, 4> rotation = {cam0_from_cam1[0], cam0_from_cam1[1],
                                            cam0_from_cam1[2], cam0_from_cam1[3]};
    const std::array<double, 3> translation = {cam0_from_cam1[4], cam0_from_cam1[5],
                                               cam0_from_cam1[6]};
    if (camera == 1) parameters.insert(parameters.end(), {rotation.data(), translation.data()});
    parameters.push_back(intrinsics.params.data());
    if (CheckTrial(*cost, parameters, measured, std::nullopt, false)) ++checked;
  }
  EXPECT_GT(checked, 30);
}

// A point outside the projection's valid domain is refused, not silently projected.
TEST(ReprojectionCost, RefusesOutsideTheValidDomain) {
  UnifiedIntrinsics camera;
  camera.params = {0.9, 300, 300, 480, 300, 0, -0.2, 0.04, 0, 0, 0};
  const Pose board = {0, 0, 0, 1, 0, 0, -1.0};  // the board 1 m behind cam0...
  const Pose rig = {0, 0, 0, 1, 0.1, 0, 0};     // ...and behind cam1
  const Eigen::Vector3d point(0.05, 0.05, 0.0);
  const std::unique_ptr<ceres::CostFunction> cost(
      ReprojectionCost::BoardCornerThroughRig(point, Eigen::Vector2d(480, 300)));
  const double* parameters[3] = {board.data(), rig.data(), camera.params.data()};
  double residual[2];
  EXPECT_FALSE(cost->Evaluate(parameters, residual, nullptr));
  const std::unique_ptr<ceres::CostFunction> direct(
      ReprojectionCost::BoardCorner(point, Eigen::Vector2d(480, 300)));
  const double* direct_parameters[2] = {board.data(), camera.params.data()};
  EXPECT_FALSE(direct->Evaluate(direct_parameters, residual, nullptr));
}

}  // namespace
}  // namespace omnirig
