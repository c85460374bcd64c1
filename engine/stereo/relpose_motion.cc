#include "engine/stereo/relpose_motion.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include <ceres/autodiff_cost_function.h>
#include <Eigen/Dense>

#include "engine/calib/board_pose.h"
#include "engine/stereo/relpose_sync.h"
#include "engine/util/check.h"

namespace omnirig {

void BoardMotionOptions::Check() const {
  OMNIRIG_CHECK(significance > 0.0 && significance < 1.0,
                "board_motion.significance must be in (0, 1), got " << significance);
  OMNIRIG_CHECK(min_std_fraction > 0.0 && min_std_fraction <= 1.0,
                "board_motion.min_std_fraction must be in (0, 1], got " << min_std_fraction);
}

ceres::CostFunction* BoardMotionLinkCost::Create(const Eigen::Vector3d& centre_in_board,
                                                 const BoardMotionPrior& prior) {
  OMNIRIG_CHECK(
      prior.rotation_std_rad > 0.0 && prior.translation_std_m > 0.0 && prior.corner_noise_px > 0.0,
      "a board motion prior needs positive standard deviations and corner noise");
  return new ceres::AutoDiffCostFunction<BoardMotionLinkCost, 6, 7, 7, 7>(
      new BoardMotionLinkCost(centre_in_board, prior.corner_noise_px / prior.rotation_std_rad,
                              prior.corner_noise_px / prior.translation_std_m));
}

BoardMotionPrior ToBoardMotionPrior(const BoardMotionEstimate& estimate,
                                    const std::array<double, 2>& corner_noise_px) {
  BoardMotionPrior prior;
  prior.rotation_std_rad = estimate.rotation_std_rad;
  prior.translation_std_m = estimate.translation_std_m;
  prior.corner_noise_px = std::sqrt(
      0.5 * (corner_noise_px[0] * corner_noise_px[0] + corner_noise_px[1] * corner_noise_px[1]));
  return prior;
}

namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

// The covariance of a camera's own board pose, in (rotation about the board's centre,
// translation of the centre), camera frame: sigma^2 (J^T J)^-1. Nullopt when a corner does not
// project or J^T J is singular.
std::optional<Matrix6d> OwnPoseCovariance(const CameraModel& camera, const Rigid3d& cam_from_board,
                                          const std::vector<Eigen::Vector3d>& points,
                                          const Eigen::Vector3d& centre, double noise_px) {
  const Eigen::Vector3d centre_in_cam = cam_from_board * centre;
  Matrix6d information = Matrix6d::Zero();
  for (const Eigen::Vector3d& point : points) {
    const Eigen::Vector3d p = cam_from_board * point;
    Eigen::Matrix<double, 2, 3> d_pixel_d_point;
    if (!ProjectWithJacobian(camera.intrinsics, p, &d_pixel_d_point)) return std::nullopt;
    // Exp(omega) (p - m) + m + t: d/d omega = -[p - m]x, d/dt = I.
    const Eigen::Vector3d r = p - centre_in_cam;
    Eigen::Matrix3d r_cross;
    r_cross << 0.0, -r.z(), r.y(), r.z(), 0.0, -r.x(), -r.y(), r.x(), 0.0;
    Eigen::Matrix<double, 2, 6> jacobian;
    jacobian.leftCols<3>() = -d_pixel_d_point * r_cross;
    jacobian.rightCols<3>() = d_pixel_d_point;
    information += jacobian.transpose() * jacobian;
  }
  const Eigen::LDLT<Matrix6d> ldlt(information);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0.0)) return std::nullopt;
  return Matrix6d(noise_px * noise_px * ldlt.solve(Matrix6d::Identity()));
}

// Step 2 of the rule for one pair: the disagreement and its corner-noise covariance.
struct PairDisagreement {
  bool ok = false;
  Vector6d delta = Vector6d::Zero();
  Matrix6d covariance = Matrix6d::Zero();
};

PairDisagreement Disagreement(const StereoRig& rig, const RigPairCorners& pair,
                              const std::array<double, 2>& noise_px) {
  PairDisagreement result;
  const auto own0 = EstimateBoardPose(rig.cam0, pair.points_in_board0, pair.pixels0);
  const auto own1 = EstimateBoardPose(rig.cam1, pair.points_in_board1, pair.pixels1);
  if (!own0 || !own1 || pair.pixels0.size() < 4 || pair.pixels1.size() < 4) return result;
  const Eigen::Vector3d centre = RigPairBoardCentre(pair);
  const auto cov0 = OwnPoseCovariance(rig.cam0, *own0, pair.points_in_board0, centre, noise_px[0]);
  const auto cov1 = OwnPoseCovariance(rig.cam1, *own1, pair.points_in_board1, centre, noise_px[1]);
  if (!cov0 || !cov1) return result;
  const Rigid3d via1 = rig.cam0_from_cam1 * *own1;
  const Eigen::AngleAxisd rotation(via1.rotation * own0->rotation.conjugate());
  result.delta.head<3>() = rotation.angle() * rotation.axis();
  result.delta.tail<3>() = via1 * centre - *own0 * centre;
  // cam1's perturbation maps into cam0's frame by the rig's rotation, both parts.
  Matrix6d rotate = Matrix6d::Zero();
  const Eigen::Matrix3d r01 = rig.cam0_from_cam1.rotation.toRotationMatrix();
  rotate.topLeftCorner<3, 3>() = r01;
  rotate.bottomRightCorner<3, 3>() = r01;
  result.covariance = *cov0 + rotate * *cov1 * rotate.transpose();
  result.ok = result.delta.allFinite() && result.covariance.allFinite();
  return result;
}

// The chi^2 upper quantile for any dof: the closed form (relpose_sync.h) while its terms stay
// in range, Wilson-Hilferty's cube-root normal approximation beyond.
double ChiSquareLimit(double alpha, int dof) {
  if (dof <= 400) return ChiSquareUpperQuantile(alpha, dof + dof % 2);
  double low = 0.0, high = 10.0;  // z with P(Z > z) = alpha
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (low + high);
    (0.5 * std::erfc(mid / std::sqrt(2.0)) > alpha ? low : high) = mid;
  }
  const double z = 0.5 * (low + high), k = dof, a = 2.0 / (9.0 * k);
  return k * std::pow(1.0 - a + z * std::sqrt(a), 3);
}

}  // namespace

BoardMotionEstimate EstimateBoardMotion(const StereoRig& rig,
                                        const std::vector<RigPairCorners>& pairs,
                                        const std::array<double, 2>& corner_noise_px,
                                        const BoardMotionOptions& options) {
  options.Check();
  OMNIRIG_CHECK(corner_noise_px[0] > 0.0 && corner_noise_px[1] > 0.0,
                "corner noise must be positive");
  BoardMotionEstimate estimate;
  estimate.corner_noise_px = corner_noise_px;
  double sum_sq[2] = {0.0, 0.0}, sum_trace[2] = {0.0, 0.0};
  for (const RigPairCorners& pair : pairs) {
    const PairDisagreement d = Disagreement(rig, pair, corner_noise_px);
    if (!d.ok) continue;
    ++estimate.num_pairs;
    for (int part = 0; part < 2; ++part) {
      sum_sq[part] += d.delta.segment<3>(3 * part).squaredNorm();
      sum_trace[part] += d.covariance.block<3, 3>(3 * part, 3 * part).trace();
    }
    estimate.statistic += d.delta.dot(d.covariance.ldlt().solve(d.delta));
  }
  const int n = estimate.num_pairs;
  if (n < 3) return estimate;
  const double raw[2] = {std::max(0.0, sum_sq[0] - sum_trace[0]) / (3.0 * (n - 1)),
                         std::max(0.0, sum_sq[1] - sum_trace[1]) / (3.0 * (n - 1))};
  const double noise[2] = {std::sqrt(sum_trace[0] / (3.0 * n)),
                           std::sqrt(sum_trace[1] / (3.0 * n))};
  estimate.raw_rotation_std_rad = std::sqrt(raw[0]);
  estimate.raw_translation_std_m = std::sqrt(raw[1]);
  estimate.noise_rotation_std_rad = noise[0];
  estimate.noise_translation_std_m = noise[1];
  estimate.dof = 6 * (n - 1);
  estimate.limit = ChiSquareLimit(options.significance, estimate.dof);
  estimate.used = estimate.statistic > estimate.limit && (raw[0] > 0.0 || raw[1] > 0.0);
  if (!estimate.used) return estimate;
  estimate.rotation_std_rad =
      std::max(estimate.raw_rotation_std_rad, options.min_std_fraction * noise[0]);
  estimate.translation_std_m =
      std::max(estimate.raw_translation_std_m, options.min_std_fraction * noise[1]);
  return estimate;
}

}  // namespace omnirig
