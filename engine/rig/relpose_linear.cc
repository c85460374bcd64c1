#include "engine/rig/relpose_linear.h"

#include <algorithm>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

namespace omnirig {

Eigen::Matrix3d ProjectToRotation(const Eigen::Matrix3d& m) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

std::optional<Rigid3d> SolveRelativePoseLinear(const std::vector<Eigen::Vector3d>& points_in_cam0,
                                               const std::vector<Eigen::Vector3d>& points_in_cam1) {
  const size_t n = points_in_cam1.size();
  if (n < 4 || points_in_cam0.size() != n) return std::nullopt;
  // The normal equations of eq. (9). Its matrix is block-diagonal in the three rows of R with
  // the shared translation, so accumulating the 4x4 moment matrix of [x1 y1 z1 1] and the
  // right-hand sides is exact and keeps memory constant in the number of corners.
  // Centring on the cam1 centroid conditions the moment matrix; the translation is recovered
  // below from the centroids.
  Eigen::Vector3d centroid1 = Eigen::Vector3d::Zero();
  for (const auto& p : points_in_cam1) centroid1 += p;
  centroid1 /= static_cast<double>(n);
  Eigen::Matrix4d moment = Eigen::Matrix4d::Zero();
  Eigen::Matrix<double, 4, 3> rhs = Eigen::Matrix<double, 4, 3>::Zero();
  for (size_t i = 0; i < n; ++i) {
    Eigen::Vector4d a;
    a << points_in_cam1[i] - centroid1, 1.0;
    moment += a * a.transpose();
    rhs += a * points_in_cam0[i].transpose();
  }
  const Eigen::JacobiSVD<Eigen::Matrix4d> svd(moment, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector4d s = svd.singularValues();
  if (!(s(3) > 1e-12 * s(0))) return std::nullopt;
  // Column j of the solution holds row j of R (first three entries) and the constant term.
  const Eigen::Matrix<double, 4, 3> solution = svd.solve(rhs);
  const Eigen::Matrix3d r_linear = solution.topRows<3>().transpose();
  const Eigen::Matrix3d rotation = ProjectToRotation(r_linear);
  Eigen::Vector3d centroid0 = Eigen::Vector3d::Zero();
  for (const auto& p : points_in_cam0) centroid0 += p;
  centroid0 /= static_cast<double>(n);
  const Eigen::Vector3d translation = centroid0 - rotation * centroid1;
  return Rigid3d(Eigen::Quaterniond(rotation), translation);
}

Rigid3d AverageRigidPoses(const std::vector<Rigid3d>& poses) {
  if (poses.empty()) return Rigid3d();
  Eigen::Matrix3d rotation_sum = Eigen::Matrix3d::Zero();
  Eigen::Vector3d translation_sum = Eigen::Vector3d::Zero();
  for (const Rigid3d& pose : poses) {
    rotation_sum += pose.RotationMatrix();
    translation_sum += pose.translation;
  }
  return Rigid3d(Eigen::Quaterniond(ProjectToRotation(rotation_sum)),
                 translation_sum / static_cast<double>(poses.size()));
}

double SpreadEigenRatio(const std::vector<Eigen::Vector3d>& points) {
  if (points.size() < 4) return 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : points) centroid += p;
  centroid /= static_cast<double>(points.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& p : points) scatter += (p - centroid) * (p - centroid).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);
  const Eigen::Vector3d values = eig.eigenvalues();  // ascending
  if (!(values(2) > 0.0)) return 0.0;
  return std::max(0.0, values(0)) / values(2);
}

}  // namespace omnirig
