#pragma once
// Trajectory accuracy against a ground truth: ATE after an SE(3) alignment (Umeyama 1991),
// relative pose error between consecutive frames, and drift as a percentage of the distance
// travelled. Both trajectories are world_from_rig poses of the same frames, in order.

#include <vector>

#include <Eigen/Core>

#include "engine/estimators/motion.h"
#include "engine/geometry/rigid3.h"
#include "engine/geometry/unified_camera.h"

namespace omnirig::slam {

struct TrajectoryErrors {
  int num_poses = 0;
  double path_length_m = 0.0;    // ground truth's distance travelled
  double ate_rmse_m = 0.0;       // absolute trajectory error after AlignRigid (SE(3))
  double ate_max_m = 0.0;
  double rpe_translation_rmse_m = 0.0;  // consecutive-frame relative pose error
  double rpe_rotation_rmse_deg = 0.0;
  // Both trajectories anchored at their first pose (the way a robot starts): the last pose's
  // position error, and the largest error of any pose, as % of the distance travelled so far.
  double final_drift_percent = 0.0;
  double max_drift_percent = 0.0;
  Rigid3d gt_from_estimate;  // the alignment used for the ATE
};

// Throws InvalidArgument when the lengths differ or fewer than 2 poses are given.
TrajectoryErrors EvaluateTrajectory(const std::vector<Rigid3d>& estimate_world_from_rig,
                                    const std::vector<Rigid3d>& gt_world_from_rig);

// How far apart two calibrations of one camera image the same bearings: the RMS, over a
// 4-pixel grid in the annulus [min_radius_px, max_radius_px] around truth's principal point,
// of the distance between each pixel and the projection with `estimate` of the bearing
// `truth` lifts it to. Pixels that do not lift or project are skipped; 0 when none remain.
double CalibrationPixelRms(const UnifiedIntrinsics& truth, const UnifiedIntrinsics& estimate,
                           double min_radius_px, double max_radius_px);

}  // namespace omnirig::slam
