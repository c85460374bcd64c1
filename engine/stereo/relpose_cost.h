#pragma once
// Ceres cost functors of the rig refinement (the paper's eq. 20: the projection function with
// the extra rigid transformation C between the two sensors). Residuals in pixels.
//
// Parameter blocks: poses as 7 doubles in Eigen order [qx, qy, qz, qw, tx, ty, tz]
// (Rigid3d::ToParams), intrinsics as UnifiedIntrinsics::params (11 doubles).

#include <array>

#include <ceres/autodiff_cost_function.h>
#include <ceres/sized_cost_function.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "engine/calib/reprojection_cost.h"
#include "engine/geometry/rigid3.h"
#include "engine/geometry/unified_camera.h"

namespace omnirig {

// A board corner seen by cam0: pixel - K D H (cam0_from_board * point_in_board).
struct RigCam0CornerCost {
  RigCam0CornerCost(const Eigen::Vector2d& observed_px, const Eigen::Vector3d& point_in_board)
      : observed_px(observed_px), point_in_board(point_in_board) {}

  template <typename T>
  bool operator()(const T* cam0_from_board, const T* intrinsics, T* residual) const {
    const T point[3] = {T(point_in_board.x()), T(point_in_board.y()), T(point_in_board.z())};
    T point_in_cam0[3];
    TransformPoint(cam0_from_board, point, point_in_cam0);
    T pixel[2];
    if (!ProjectToPixel(intrinsics, point_in_cam0, pixel)) return false;
    residual[0] = pixel[0] - T(observed_px.x());
    residual[1] = pixel[1] - T(observed_px.y());
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector2d& observed_px,
                                     const Eigen::Vector3d& point_in_board) {
    return new ceres::AutoDiffCostFunction<RigCam0CornerCost, 2, 7, UnifiedIntrinsics::kNumParams>(
        new RigCam0CornerCost(observed_px, point_in_board));
  }

  Eigen::Vector2d observed_px;
  Eigen::Vector3d point_in_board;
};

// A board corner seen by cam1 of the same pair: the corner goes through the board pose in cam0
// and then cam1_from_cam0 = cam0_from_cam1^-1, so the rig pose is shared by every pair.
struct RigCam1CornerCost {
  RigCam1CornerCost(const Eigen::Vector2d& observed_px, const Eigen::Vector3d& point_in_board)
      : observed_px(observed_px), point_in_board(point_in_board) {}

  template <typename T>
  bool operator()(const T* cam0_from_board, const T* cam0_from_cam1, const T* intrinsics,
                  T* residual) const {
    const T point[3] = {T(point_in_board.x()), T(point_in_board.y()), T(point_in_board.z())};
    T point_in_cam0[3];
    TransformPoint(cam0_from_board, point, point_in_cam0);
    const Eigen::Map<const Eigen::Quaternion<T>> rotation(cam0_from_cam1);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> translation(cam0_from_cam1 + 4);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> p0(point_in_cam0);
    const Eigen::Matrix<T, 3, 1> point_in_cam1 = rotation.conjugate() * (p0 - translation);
    T pixel[2];
    if (!ProjectToPixel(intrinsics, point_in_cam1.data(), pixel)) return false;
    residual[0] = pixel[0] - T(observed_px.x());
    residual[1] = pixel[1] - T(observed_px.y());
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector2d& observed_px,
                                     const Eigen::Vector3d& point_in_board) {
    return new ceres::AutoDiffCostFunction<RigCam1CornerCost, 2, 7, 7,
                                           UnifiedIntrinsics::kNumParams>(
        new RigCam1CornerCost(observed_px, point_in_board));
  }

  Eigen::Vector2d observed_px;
  Eigen::Vector3d point_in_board;
};

// d(q * v) / d[qx, qy, qz, qw] of Eigen's rotation v + 2 w (u x v) + 2 u x (u x v), u = (qx,
// qy, qz), w = qw (the formula itself, so also off the unit sphere, as the Jets see it).
inline Eigen::Matrix<double, 3, 4> RotatedPointJacobian(const Eigen::Quaterniond& q,
                                                        const Eigen::Vector3d& v) {
  const Eigen::Vector3d u = q.vec();
  Eigen::Matrix3d v_cross;
  v_cross << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  Eigen::Matrix<double, 3, 4> jacobian;
  jacobian.leftCols<3>() = -2.0 * q.w() * v_cross + 2.0 * u.dot(v) * Eigen::Matrix3d::Identity() +
                           2.0 * u * v.transpose() - 4.0 * v * u.transpose();
  jacobian.col(3) = 2.0 * u.cross(v);
  return jacobian;
}

// RigCam1CornerCost with hand-written Jacobians: the rig's solves spent most of their time in
// the 25-dimensional Jets of that functor (with this, one estimate on the real fisheye pairs of
// bench_relpose takes 2.5 s of CPU instead of 6). The same residual by the same operations;
// Jacobians with respect to the ambient 7 + 7 + 11 parameters, equal to the Jets' to round-off
// (relpose_cost_test.cc). A constant block (null Jacobian pointer) costs nothing.
// The projection and its intrinsics Jacobian are the calibration's BoardCornerAnalyticCost,
// evaluated at the point already in cam1 (an identity pose block and a board point at zero).
class RigCam1CornerAnalyticCost
    : public ceres::SizedCostFunction<2, 7, 7, UnifiedIntrinsics::kNumParams> {
 public:
  RigCam1CornerAnalyticCost(const Eigen::Vector2d& observed_px,
                            const Eigen::Vector3d& point_in_board)
      : point_in_board_(point_in_board), projection_(Eigen::Vector3d::Zero(), observed_px) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const Eigen::Map<const Eigen::Quaterniond> board_rotation(parameters[0]);
    const Eigen::Map<const Eigen::Vector3d> board_translation(parameters[0] + 4);
    const Eigen::Map<const Eigen::Quaterniond> rig_rotation(parameters[1]);
    const Eigen::Map<const Eigen::Vector3d> rig_translation(parameters[1] + 4);
    const Eigen::Vector3d point_in_cam0 = board_rotation * point_in_board_ + board_translation;
    const Eigen::Vector3d offset = point_in_cam0 - rig_translation;
    const Eigen::Quaterniond cam1_from_cam0 = rig_rotation.conjugate();
    const Eigen::Vector3d point_in_cam1 = cam1_from_cam0 * offset;
    const double at_point[7] = {0.0, 0.0, 0.0, 1.0,
                                point_in_cam1.x(), point_in_cam1.y(), point_in_cam1.z()};
    const double* projection_parameters[2] = {parameters[2], at_point};
    const bool want_poses =
        jacobians != nullptr && (jacobians[0] != nullptr || jacobians[1] != nullptr);
    Eigen::Matrix<double, 2, 7, Eigen::RowMajor> d_pixel_d_at_point;
    double* projection_jacobians[2] = {jacobians != nullptr ? jacobians[2] : nullptr,
                                       want_poses ? d_pixel_d_at_point.data() : nullptr};
    if (!projection_.Evaluate(projection_parameters, residuals,
                              jacobians != nullptr ? projection_jacobians : nullptr)) {
      return false;
    }
    if (!want_poses) return true;
    const Eigen::Matrix<double, 2, 3> d_pixel_d_point = d_pixel_d_at_point.rightCols<3>();
    // point_in_cam1 is linear in point_in_cam0 (the formula's matrix, as for the Jets).
    const Eigen::Matrix3d d_cam1_d_cam0 = cam1_from_cam0.toRotationMatrix();
    const Eigen::Matrix<double, 2, 3> d_pixel_d_cam0 = d_pixel_d_point * d_cam1_d_cam0;
    if (jacobians[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> jacobian(jacobians[0]);
      jacobian.leftCols<4>() = d_pixel_d_cam0 * RotatedPointJacobian(board_rotation, point_in_board_);
      jacobian.rightCols<3>() = d_pixel_d_cam0;
    }
    if (jacobians[1] != nullptr) {
      // The conjugate negates the vector part: d/du = -(d/du' at u' = -u).
      Eigen::Matrix<double, 3, 4> d_cam1_d_rotation = RotatedPointJacobian(cam1_from_cam0, offset);
      d_cam1_d_rotation.leftCols<3>() *= -1.0;
      Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> jacobian(jacobians[1]);
      jacobian.leftCols<4>() = d_pixel_d_point * d_cam1_d_rotation;
      jacobian.rightCols<3>() = -d_pixel_d_cam0;
    }
    return true;
  }

 private:
  Eigen::Vector3d point_in_board_;
  BoardCornerAnalyticCost projection_;
};

// A board corner of one pair with the rig and the camera held constant: the board pose is the
// only parameter block, so the autodiff carries 7 derivatives instead of the 25 of the rig's
// functors (the synchronisation test fits every pair's board this way in every round).
struct BoardThroughRigCost {
  BoardThroughRigCost(const Eigen::Vector2d& observed_px, const Eigen::Vector3d& point_in_board,
                      const Rigid3d& cam_from_cam0, const UnifiedIntrinsics& intrinsics)
      : observed_px(observed_px), cam_from_cam0(cam_from_cam0), intrinsics(intrinsics.params) {
    for (int k = 0; k < 3; ++k) point[k] = point_in_board[k];
  }

  template <typename T>
  bool operator()(const T* cam0_from_board, T* residual) const {
    const T point_in_board[3] = {T(point[0]), T(point[1]), T(point[2])};
    T point_in_cam0[3];
    TransformPoint(cam0_from_board, point_in_board, point_in_cam0);
    const Eigen::Matrix<T, 3, 1> point_in_cam =
        cam_from_cam0.rotation.cast<T>() *
            Eigen::Map<const Eigen::Matrix<T, 3, 1>>(point_in_cam0) +
        cam_from_cam0.translation.cast<T>();
    T params[UnifiedIntrinsics::kNumParams];
    for (int p = 0; p < UnifiedIntrinsics::kNumParams; ++p) params[p] = T(intrinsics[p]);
    T pixel[2];
    if (!ProjectToPixel(params, point_in_cam.data(), pixel)) return false;
    residual[0] = pixel[0] - T(observed_px.x());
    residual[1] = pixel[1] - T(observed_px.y());
    return true;
  }

  Eigen::Vector2d observed_px;
  double point[3];
  Rigid3d cam_from_cam0;
  std::array<double, UnifiedIntrinsics::kNumParams> intrinsics;
};

}  // namespace omnirig
