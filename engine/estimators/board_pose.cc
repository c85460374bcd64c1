#include "engine/estimators/board_pose.h"

#include <cmath>

#include <ceres/ceres.h>
#include <Eigen/SVD>

#include "engine/geometry/ceres_problem.h"
#include "engine/geometry/reprojection_cost.h"

namespace omnirig {
namespace {

// Conditioning of the DLT: centres the board points and scales them to unit mean distance.
Eigen::Matrix3d NormalisingTransform(const std::vector<Eigen::Vector3d>& object_points) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& p : object_points) mean += p.head<2>();
  mean /= static_cast<double>(object_points.size());
  double spread = 0.0;
  for (const auto& p : object_points) spread += (p.head<2>() - mean).norm();
  spread = std::max(spread / static_cast<double>(object_points.size()), 1e-12);
  Eigen::Matrix3d n = Eigen::Matrix3d::Identity();
  n(0, 0) = n(1, 1) = 1.0 / spread;
  n(0, 2) = -mean.x() / spread;
  n(1, 2) = -mean.y() / spread;
  return n;
}

// RMS pixel residual of a pose, or infinity when a corner does not project.
double PoseRmsPx(const CameraModel& camera, const std::vector<Eigen::Vector3d>& object_points,
                 const std::vector<Eigen::Vector2d>& corners_px, const Rigid3d& cam_from_board) {
  double sum2 = 0.0;
  for (size_t i = 0; i < object_points.size(); ++i) {
    const auto pixel = Project(camera.intrinsics, cam_from_board * object_points[i]);
    if (!pixel) return std::numeric_limits<double>::infinity();
    sum2 += (*pixel - corners_px[i]).squaredNorm();
  }
  return std::sqrt(sum2 / static_cast<double>(object_points.size()));
}

}  // namespace

std::optional<Rigid3d> BoardPoseFromBearings(const std::vector<Eigen::Vector3d>& object_points,
                                             const std::vector<Eigen::Vector3d>& bearings) {
  const int n = static_cast<int>(object_points.size());
  if (n < 4 || bearings.size() != object_points.size()) return std::nullopt;
  const Eigen::Matrix3d normalise = NormalisingTransform(object_points);
  // b x (H p) = 0: three rows per point, two of them independent.
  Eigen::MatrixXd a(3 * n, 9);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d p =
        normalise * Eigen::Vector3d(object_points[i].x(), object_points[i].y(), 1.0);
    const Eigen::Vector3d& b = bearings[i];
    const Eigen::RowVector3d pt = p.transpose();
    a.row(3 * i) << Eigen::RowVector3d::Zero(), -b.z() * pt, b.y() * pt;
    a.row(3 * i + 1) << b.z() * pt, Eigen::RowVector3d::Zero(), -b.x() * pt;
    a.row(3 * i + 2) << -b.y() * pt, b.x() * pt, Eigen::RowVector3d::Zero();
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeFullV);
  const Eigen::VectorXd h = svd.matrixV().col(8);
  Eigen::Matrix3d homography;
  homography << h.segment<3>(0).transpose(), h.segment<3>(3).transpose(),
      h.segment<3>(6).transpose();
  homography = homography * normalise;
  // Sign: the board lies along the bearings, not opposite to them.
  double side = 0.0;
  for (int i = 0; i < n; ++i) {
    side += bearings[i].dot(homography *
                            Eigen::Vector3d(object_points[i].x(), object_points[i].y(), 1.0));
  }
  if (side < 0.0) homography = -homography;
  const double scale = 2.0 / (homography.col(0).norm() + homography.col(1).norm());
  if (!std::isfinite(scale)) return std::nullopt;
  Eigen::Matrix3d rotation;
  rotation.col(0) = homography.col(0) * scale;
  rotation.col(1) = homography.col(1) * scale;
  rotation.col(2) = rotation.col(0).cross(rotation.col(1));
  const Eigen::JacobiSVD<Eigen::Matrix3d> rsvd(rotation, Eigen::ComputeFullU | Eigen::ComputeFullV);
  rotation = rsvd.matrixU() * rsvd.matrixV().transpose();
  if (rotation.determinant() < 0.0) return std::nullopt;
  return Rigid3d(Eigen::Quaterniond(rotation), homography.col(2) * scale);
}

std::optional<Rigid3d> EstimateBoardPose(const CameraModel& camera,
                                         const std::vector<Eigen::Vector3d>& object_points,
                                         const std::vector<Eigen::Vector2d>& corners_px,
                                         double* rms_px) {
  if (object_points.size() < 4 || object_points.size() != corners_px.size()) return std::nullopt;
  std::vector<Eigen::Vector3d> bearings;
  bearings.reserve(corners_px.size());
  for (const auto& corner : corners_px) {
    const auto bearing = Lift(camera.intrinsics, corner);
    if (!bearing) return std::nullopt;
    bearings.push_back(*bearing);
  }
  const std::optional<Rigid3d> initial = BoardPoseFromBearings(object_points, bearings);
  if (!initial || !std::isfinite(PoseRmsPx(camera, object_points, corners_px, *initial))) {
    return std::nullopt;
  }
  std::array<double, 7> pose = initial->ToParams();
  // The calibration's analytic residual with the intrinsics held constant (Ceres then asks for
  // the pose Jacobian only): several times faster than autodiff, and the closed-form
  // initialisation runs this for every view.
  std::array<double, UnifiedIntrinsics::kNumParams> intrinsics = camera.intrinsics.params;
  ceres::Problem problem;
  for (size_t i = 0; i < object_points.size(); ++i) {
    problem.AddResidualBlock(ReprojectionCost::BoardCorner(object_points[i], corners_px[i]),
                             nullptr, pose.data(), intrinsics.data());
  }
  problem.SetParameterBlockConstant(intrinsics.data());
  problem.SetManifold(pose.data(), NewPoseManifold());
  const ceres::Solver::Options options =
      MakeSolverOptions(SolverSetup(0, 50).Tolerances(1e-10, 1e-10, 1e-10));
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  const Rigid3d cam_from_board = Rigid3d::FromParams(pose.data());
  const double rms = PoseRmsPx(camera, object_points, corners_px, cam_from_board);
  if (!std::isfinite(rms)) return std::nullopt;
  if (rms_px) *rms_px = rms;
  return cam_from_board;
}

}  // namespace omnirig
