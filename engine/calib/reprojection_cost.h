#pragma once
// Residuals of the calibration problem (the paper's eq. 7), in pixels.

#include <ceres/autodiff_cost_function.h>
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
    const T point[3] = {T(point_in_board_.x()), T(point_in_board_.y()),
                        T(point_in_board_.z())};
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

// The same residual with the intrinsics held as a constant, for pose-only problems.
struct BoardCornerPoseCost {
  BoardCornerPoseCost(const UnifiedIntrinsics& intrinsics, const Eigen::Vector3d& point_in_board,
                      const Eigen::Vector2d& measured_px)
      : intrinsics_(intrinsics), corner_(point_in_board, measured_px) {}

  template <typename T>
  bool operator()(const T* cam_from_board, T* residuals) const {
    T intrinsics[UnifiedIntrinsics::kNumParams];
    for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
      intrinsics[i] = T(intrinsics_.params[i]);
    }
    return corner_(intrinsics, cam_from_board, residuals);
  }

  static ceres::CostFunction* Create(const UnifiedIntrinsics& intrinsics,
                                     const Eigen::Vector3d& point_in_board,
                                     const Eigen::Vector2d& measured_px) {
    return new ceres::AutoDiffCostFunction<BoardCornerPoseCost, 2, 7>(
        new BoardCornerPoseCost(intrinsics, point_in_board, measured_px));
  }

 private:
  UnifiedIntrinsics intrinsics_;
  BoardCornerCost corner_;
};

}  // namespace omnirig
