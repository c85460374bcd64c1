#pragma once
// The pose of a calibration board seen by a camera whose model is known.

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"

namespace omnirig {

// Pose-only least squares with the model fixed: a linear initial pose from the lifted bearings
// (a homography between the board plane and the bearings), then Levenberg-Marquardt on the
// pixel reprojection error. Returns nullopt for fewer than 4 correspondences, bearings that do
// not lift, or a pose that puts the board behind the camera. `rms_px` receives the RMS of the
// pixel residuals at the solution.
std::optional<Rigid3d> EstimateBoardPose(const CameraModel& camera,
                                         const std::vector<Eigen::Vector3d>& object_points,
                                         const std::vector<Eigen::Vector2d>& corners_px,
                                         double* rms_px = nullptr);

// The linear step alone: the board pose from unit bearings of planar points (z = 0 in the
// board frame) by a DLT on the bearing-homography constraint bearing x (H [X Y 1]) = 0.
std::optional<Rigid3d> BoardPoseFromBearings(const std::vector<Eigen::Vector3d>& object_points,
                                             const std::vector<Eigen::Vector3d>& bearings);

}  // namespace omnirig
