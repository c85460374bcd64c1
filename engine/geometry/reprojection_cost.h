#pragma once
// The one residual family of the engine's reprojection problems: calibration (the paper's
// eq. 7), the rig's relative pose (eq. 20) and bundle adjustment (eqs. 19-23). A point is
// carried by a pose, then optionally by the rig, then projected (engine/geometry/
// unified_camera.h); the residual, in pixels, is the projection minus the measured pixel:
//
//   point_in_cam = rig(pose * point),  residual = Project(intrinsics, point_in_cam) - measured.
//
// Parameter blocks, in this order, those that are parameters:
//   pose        [7]  always: cam_from_board, cam0_from_board or rig_from_world
//   point       [3]  a landmark's point_in_world; a board corner is a constant instead
//   rig              none; a constant cam_from_x applied forward; or cam0_from_cam1 as
//                    parameters, applied inverted (the pose brings the point into cam0, the
//                    camera is cam1): one block [7], or a rotation [4] and a translation [3]
//   intrinsics [11]  UnifiedIntrinsics::params, when a parameter; else a constant
// Poses are Rigid3d::ToParams blocks (Eigen order [qx, qy, qz, qw, tx, ty, tz]). The Jacobians
// are analytic, with respect to the ambient parameters (the manifolds map them to tangent
// spaces) and exact for non-unit quaternions too; a constant block (null Jacobian) costs
// nothing. Tested with ceres::GradientChecker (reprojection_cost_test.cc).

#include <array>
#include <optional>

#include <ceres/cost_function.h>
#include <Eigen/Core>

#include "engine/geometry/rigid3.h"
#include "engine/geometry/unified_camera.h"

namespace omnirig {

class ReprojectionCost : public ceres::CostFunction {
 public:
  // A board corner seen by a camera (calibration): blocks (cam_from_board, intrinsics).
  static ReprojectionCost* BoardCorner(const Eigen::Vector3d& point_in_board,
                                       const Eigen::Vector2d& measured_px);
  // A board corner seen by cam1 of a rig: blocks (cam0_from_board, cam0_from_cam1, intrinsics).
  static ReprojectionCost* BoardCornerThroughRig(const Eigen::Vector3d& point_in_board,
                                                 const Eigen::Vector2d& measured_px);
  // A board corner with the camera constant: block (cam0_from_board); the camera is reached
  // by the constant cam_from_cam0.
  static ReprojectionCost* BoardCornerFixedCamera(const Eigen::Vector3d& point_in_board,
                                                  const Eigen::Vector2d& measured_px,
                                                  const Rigid3d& cam_from_cam0,
                                                  const UnifiedIntrinsics& intrinsics);
  // A landmark seen by one camera of the rig, the calibration constant: blocks
  // (rig_from_world, point_in_world).
  static ReprojectionCost* Landmark(const Eigen::Vector2d& measured_px, const Rigid3d& cam_from_rig,
                                    const UnifiedIntrinsics& intrinsics);
  // A landmark with the calibration as parameters (the rig frame is cam0's): camera 0 has
  // blocks (rig_from_world, point_in_world, intrinsics), camera 1 (rig_from_world,
  // point_in_world, cam0_from_cam1 rotation [4], translation [3], intrinsics).
  static ReprojectionCost* LandmarkWithCalibration(int camera, const Eigen::Vector2d& measured_px);

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  enum class Rig { kNone, kConstant, kBlock, kRotationTranslationBlocks };
  // A posed point carried into the camera by the rig, with what the Jacobians need.
  struct ThroughRig {
    Eigen::Vector3d point_in_cam;
    Eigen::Matrix3d d_cam_d_posed = Eigen::Matrix3d::Identity();
    // A parameterised rig: cam0_from_cam1's inverse rotation and the posed point minus its
    // translation (identity and zero otherwise).
    Eigen::Quaterniond cam1_from_cam0 = Eigen::Quaterniond::Identity();
    Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  };
  ReprojectionCost(const Eigen::Vector2d& measured_px, const std::optional<Eigen::Vector3d>& point,
                   Rig rig, const Rigid3d& cam_from_x,
                   const std::optional<UnifiedIntrinsics>& intrinsics);
  ThroughRig CarryThroughRig(double const* const* parameters, const Eigen::Vector3d& posed) const;
  // d pixel / d (the rig's blocks), given d pixel / d point_in_cam and d pixel / d posed.
  void RigJacobians(const Eigen::Matrix<double, 2, 3>& d_pixel_d_cam,
                    const Eigen::Matrix<double, 2, 3>& d_pixel_d_posed, const ThroughRig& rig,
                    double** jacobians) const;

  Eigen::Vector2d measured_px_;
  std::optional<Eigen::Vector3d> point_;  // constant point; nullopt: a parameter block
  Rig rig_;
  // Where each block stands in the parameters (-1: a constant, no Jacobian); kBlock holds the
  // rig's rotation and translation in one block.
  int point_block_ = -1, rotation_block_ = -1, translation_block_ = -1, intrinsics_block_ = -1;
  Eigen::Matrix3d cam_from_x_rotation_;   // Rig::kConstant
  Eigen::Vector3d cam_from_x_translation_;
  std::optional<std::array<double, UnifiedIntrinsics::kNumParams>> intrinsics_;  // constant
};

}  // namespace omnirig
