#pragma once
// Ceres cost functors of the rig refinement (the paper's eq. 20: the projection function with
// the extra rigid transformation C between the two sensors). Residuals in pixels.
//
// Parameter blocks: poses as 7 doubles in Eigen order [qx, qy, qz, qw, tx, ty, tz]
// (Rigid3d::ToParams), intrinsics as UnifiedIntrinsics::params (11 doubles).

#include <array>

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
