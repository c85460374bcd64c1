#pragma once
// Residuals of the calibration problem (the paper's eq. 7), in pixels.

#include <ceres/autodiff_cost_function.h>
#include <ceres/sized_cost_function.h>
#include <Eigen/Core>

#include "engine/geometry/rigid3.h"
#include "engine/geometry/unified_camera.h"

namespace omnirig {

// Reprojection error of one board corner: measured pixel minus the projection of the corner
// through cam_from_board (7-double block) and the intrinsics (11-double block).
struct BoardCornerCost {
  BoardCornerCost(const Eigen::Vector3d& point_in_board, const Eigen::Vector2d& measured_px)
      : point_in_board_(point_in_board), measured_px_(measured_px) {}

  template <typename T>
  bool operator()(const T* intrinsics, const T* cam_from_board, T* residuals) const {
    const T point[3] = {T(point_in_board_.x()), T(point_in_board_.y()), T(point_in_board_.z())};
    T point_in_cam[3];
    TransformPoint(cam_from_board, point, point_in_cam);
    T pixel[2];
    if (!ProjectToPixel(intrinsics, point_in_cam, pixel)) return false;
    residuals[0] = pixel[0] - T(measured_px_.x());
    residuals[1] = pixel[1] - T(measured_px_.y());
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& point_in_board,
                                     const Eigen::Vector2d& measured_px) {
    return new ceres::AutoDiffCostFunction<BoardCornerCost, 2, UnifiedIntrinsics::kNumParams, 7>(
        new BoardCornerCost(point_in_board, measured_px));
  }

 private:
  Eigen::Vector3d point_in_board_;
  Eigen::Vector2d measured_px_;
};

// BoardCornerCost with hand-written Jacobians: the calibration solve spends most of its time
// evaluating Jacobians, and the autodiff version (18-dimensional Jets through the quaternion
// rotation, the projection and the distortion) is about ten times slower than this. The same
// residual, the same valid domain (tested against BoardCornerCost in calibrate_test.cc). The
// pose Jacobian is with respect to the 7 ambient parameters [qx, qy, qz, qw, tx, ty, tz] of
// Eigen's q * p + t; the pose manifold maps it to the tangent space.
class BoardCornerAnalyticCost
    : public ceres::SizedCostFunction<2, UnifiedIntrinsics::kNumParams, 7> {
 public:
  BoardCornerAnalyticCost(const Eigen::Vector3d& point_in_board, const Eigen::Vector2d& measured_px)
      : point_in_board_(point_in_board), measured_px_(measured_px) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    using I = UnifiedIntrinsics;
    const double* p = parameters[0];
    const Eigen::Map<const Eigen::Quaterniond> q(parameters[1]);
    const Eigen::Map<const Eigen::Vector3d> t(parameters[1] + 4);
    const Eigen::Vector3d point_in_cam = q * point_in_board_ + t;
    double pixel[2];
    if (!ProjectToPixel(p, point_in_cam.data(), pixel)) return false;
    residuals[0] = pixel[0] - measured_px_.x();
    residuals[1] = pixel[1] - measured_px_.y();
    if (jacobians == nullptr || (jacobians[0] == nullptr && jacobians[1] == nullptr)) return true;

    // The chain of eqs. (2)-(4): point -> unit sphere s -> normalised plane m -> distorted
    // m_d -> pixel.
    const double norm = point_in_cam.norm();
    const Eigen::Vector3d s = point_in_cam / norm;
    const double denom = s.z() + p[I::kXi];
    const double x = s.x() / denom, y = s.y() / denom;
    const double rho2 = x * x + y * y, rho4 = rho2 * rho2;
    const double radial = 1 + p[I::kK1] * rho2 + p[I::kK2] * rho4 + p[I::kK5] * rho4 * rho2;
    const double dradial_drho2 = p[I::kK1] + 2 * p[I::kK2] * rho2 + 3 * p[I::kK5] * rho4;
    const double k3 = p[I::kK3], k4 = p[I::kK4];
    const double xd = x * radial + 2 * k3 * x * y + k4 * (rho2 + 2 * x * x);
    const double yd = y * radial + 2 * k4 * x * y + k3 * (rho2 + 2 * y * y);
    Eigen::Matrix2d dmd_dm;
    dmd_dm(0, 0) = radial + 2 * x * x * dradial_drho2 + 2 * k3 * y + 6 * k4 * x;
    dmd_dm(0, 1) = 2 * x * y * dradial_drho2 + 2 * k3 * x + 2 * k4 * y;
    dmd_dm(1, 0) = 2 * x * y * dradial_drho2 + 2 * k4 * y + 2 * k3 * x;
    dmd_dm(1, 1) = radial + 2 * y * y * dradial_drho2 + 2 * k4 * x + 6 * k3 * y;
    Eigen::Matrix2d dp_dmd;
    dp_dmd << p[I::kGammaU], p[I::kGammaU] * p[I::kAlpha], 0.0, p[I::kGammaV];
    const Eigen::Matrix2d dp_dm = dp_dmd * dmd_dm;

    if (jacobians[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 2, I::kNumParams, Eigen::RowMajor>> J(jacobians[0]);
      J.setZero();
      J.col(I::kXi) = dp_dm * Eigen::Vector2d(-x / denom, -y / denom);
      J(0, I::kGammaU) = xd + p[I::kAlpha] * yd;
      J(1, I::kGammaV) = yd;
      J(0, I::kU0) = 1.0;
      J(1, I::kV0) = 1.0;
      J(0, I::kAlpha) = p[I::kGammaU] * yd;
      J.col(I::kK1) = dp_dmd * Eigen::Vector2d(x * rho2, y * rho2);
      J.col(I::kK2) = dp_dmd * Eigen::Vector2d(x * rho4, y * rho4);
      J.col(I::kK3) = dp_dmd * Eigen::Vector2d(2 * x * y, rho2 + 2 * y * y);
      J.col(I::kK4) = dp_dmd * Eigen::Vector2d(rho2 + 2 * x * x, 2 * x * y);
      J.col(I::kK5) = dp_dmd * Eigen::Vector2d(x * rho4 * rho2, y * rho4 * rho2);
    }
    if (jacobians[1] != nullptr) {
      // d s / d X = (I - s s^T) / |X|;  d m / d s from m = (s_x, s_y) / (s_z + xi).
      const Eigen::Matrix3d ds_dX = (Eigen::Matrix3d::Identity() - s * s.transpose()) / norm;
      Eigen::Matrix<double, 2, 3> dm_ds;
      dm_ds << 1.0 / denom, 0.0, -x / denom, 0.0, 1.0 / denom, -y / denom;
      const Eigen::Matrix<double, 2, 3> dp_dX = dp_dm * dm_ds * ds_dX;
      // Eigen rotates by X = v + 2 w (u x v) + 2 u x (u x v), u = (qx, qy, qz), w = qw.
      const Eigen::Vector3d& v = point_in_board_;
      const Eigen::Vector3d u = q.vec();
      const double w = q.w();
      Eigen::Matrix3d v_cross;
      v_cross << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
      Eigen::Matrix<double, 3, 4> dX_dq;
      dX_dq.leftCols<3>() = -2.0 * w * v_cross + 2.0 * u.dot(v) * Eigen::Matrix3d::Identity() +
                            2.0 * u * v.transpose() - 4.0 * v * u.transpose();
      dX_dq.col(3) = 2.0 * u.cross(v);
      Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> J(jacobians[1]);
      J.leftCols<4>() = dp_dX * dX_dq;
      J.rightCols<3>() = dp_dX;
    }
    return true;
  }

 private:
  Eigen::Vector3d point_in_board_;
  Eigen::Vector2d measured_px_;
};

}  // namespace omnirig
