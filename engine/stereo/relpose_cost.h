#pragma once
// Ceres cost functors of the rig refinement (the paper's eq. 20: the projection function with
// the extra rigid transformation C between the two sensors). Residuals in pixels.
//
// Parameter blocks: poses as 7 doubles in Eigen order [qx, qy, qz, qw, tx, ty, tz]
// (Rigid3d::ToParams), intrinsics as UnifiedIntrinsics::params (11 doubles).

#include <ceres/autodiff_cost_function.h>
#include <Eigen/Core>

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

}  // namespace omnirig
