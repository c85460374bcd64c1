#pragma once
// Bundle adjustment of the stereo rig as one device (the paper's eqs. 19-23): the residuals are
// the reprojection errors (pixels) of every landmark in both cameras of every rig pose that
// sees it, cam1 reached through the fixed cam0_from_cam1 (eq. 20). Parameters are rig poses
// (rig_from_world, one 7-double block each) and landmark positions; the calibration is fixed.
// Points are eliminated first (Schur complement), DENSE_SCHUR or SPARSE_SCHUR chosen by the
// number of free poses.

#include <string>
#include <vector>

#include <ceres/ceres.h>

#include "engine/geometry/camera_model.h"
#include "engine/slam/map.h"
#include "engine/util/progress.h"

namespace omnirig::slam {

// Reprojection of a world point into one camera of the rig, with hand-written Jacobians
// (tested against automatic differentiation). Parameter blocks: rig_from_world in Eigen order
// [qx, qy, qz, qw, tx, ty, tz] and point_in_world [x, y, z]. Residual in pixels.
class RigReprojectionCost : public ceres::SizedCostFunction<2, 7, 3> {
 public:
  RigReprojectionCost(const UnifiedIntrinsics& intrinsics, const Rigid3d& cam_from_rig,
                      const Eigen::Vector2d& observed_pixel);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  UnifiedIntrinsics intrinsics_;
  Eigen::Matrix3d cam_from_rig_rotation_;
  Eigen::Vector3d cam_from_rig_translation_;
  Eigen::Vector2d observed_pixel_;
};

// The same residual templated for Ceres' automatic differentiation; the reference the
// analytic Jacobians are checked against.
struct RigReprojectionAutoDiff {
  RigReprojectionAutoDiff(const UnifiedIntrinsics& intrinsics, const Rigid3d& cam_from_rig,
                          const Eigen::Vector2d& observed_pixel)
      : intrinsics(intrinsics), cam_from_rig(cam_from_rig.ToParams()), observed(observed_pixel) {}
  template <typename T>
  bool operator()(const T* rig_from_world, const T* point_in_world, T* residuals) const {
    T point_in_rig[3], point_in_cam[3], pixel[2], cam_params[7], intr[UnifiedIntrinsics::kNumParams];
    for (int i = 0; i < 7; ++i) cam_params[i] = T(cam_from_rig[i]);
    for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) intr[i] = T(intrinsics.params[i]);
    TransformPoint(rig_from_world, point_in_world, point_in_rig);
    TransformPoint(cam_params, point_in_rig, point_in_cam);
    if (!ProjectToPixel(intr, point_in_cam, pixel)) return false;
    residuals[0] = pixel[0] - T(observed.x());
    residuals[1] = pixel[1] - T(observed.y());
    return true;
  }
  UnifiedIntrinsics intrinsics;
  std::array<double, 7> cam_from_rig;
  Eigen::Vector2d observed;
};

// cam_from_rig for camera 0 or 1 of a rig whose frame is cam0's.
Rigid3d CamFromRig(const StereoRig& rig, int camera);

struct BundleAdjustmentOptions {
  double huber_scale_px = 1.5;       // robust loss: quadratic below, linear above
  double max_reprojection_error_px = 3.0;  // observations above this are pruned after a solve
  int max_iterations = 30;
  int num_threads = 1;
  int max_dense_schur_poses = 120;   // above this many free poses, SPARSE_SCHUR
  void Check() const;
};

struct BundleAdjustmentReport {
  int num_free_poses = 0;
  int num_constant_poses = 0;
  int num_points = 0;
  int num_residuals = 0;  // 2 per observation
  int iterations = 0;
  double initial_rms_px = 0.0;  // before the first solve, over every observation used
  double final_rms_px = 0.0;    // after pruning and the final solve, over the inliers
  int num_observations_pruned = 0;
  int num_points_pruned = 0;
  std::string linear_solver;
  std::string termination;
  double time_s = 0.0;
};

// Adjusts the poses of `free_frames` and every valid landmark they observe from at least two
// rig positions (a landmark seen from one position says nothing about poses). Observations of
// those landmarks from other frames with a pose enter with that pose held constant. When no
// such constant pose exists, the first free frame is held constant (the gauge: stereo fixes
// the scale, one pose fixes the other six degrees of freedom). Observations with a final error
// above options.max_reprojection_error_px are removed from the map, and landmarks left with
// fewer than two observations are marked invalid. Reports every solver iteration to `progress`
// (stage "bundle_adjustment", fractions increasing over both solves) and stops within one
// iteration of a cancellation: the solver aborts and Cancelled is thrown, leaving the map as
// it was before that solve.
BundleAdjustmentReport BundleAdjust(const StereoRig& rig, const std::vector<int>& free_frames,
                                    const BundleAdjustmentOptions& options, SlamMap* map,
                                    const ProgressSink& progress = ProgressSink());

// Pose-only refinement of one frame against fixed landmarks (motion-only bundle adjustment):
// `observations[i]` measures `points_in_world[i]`. Returns the refined rig_from_world and
// writes per-observation inlier flags (final error under max_reprojection_error_px).
Rigid3d RefineRigPose(const StereoRig& rig, const Rigid3d& rig_from_world_init,
                      const std::vector<Observation>& observations,
                      const std::vector<Eigen::Vector3d>& points_in_world,
                      const BundleAdjustmentOptions& options, std::vector<bool>* inliers);

}  // namespace omnirig::slam
