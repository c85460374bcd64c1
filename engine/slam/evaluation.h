#pragma once
// Trajectory accuracy against a ground truth: ATE after an SE(3) alignment (Umeyama 1991),
// relative pose error between consecutive frames and over fixed lengths of path, each frame's
// error against the distance travelled, and drift as a percentage of the distance travelled
// (the figures evo and the KITTI benchmark report). Both trajectories are world_from_rig poses
// of the same frames, in order.

#include <vector>

#include <Eigen/Core>

#include "engine/estimators/motion.h"
#include "engine/geometry/rigid3.h"
#include "engine/geometry/unified_camera.h"

namespace omnirig::slam {

// Relative pose error over segments of a fixed length of the ground truth's path (evo_rpe with
// --delta L --delta_unit m; KITTI's segments): every frame starts a segment that ends at the
// first frame at least length_m further along the path.
struct SegmentErrors {
  double length_m = 0.0;
  int num_segments = 0;  // 0 when the path is shorter than length_m
  double translation_rmse_m = 0.0;
  double translation_mean_percent = 0.0;  // mean of the error over the segment's length
  double rotation_rmse_deg = 0.0;
};

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
  // Per frame, in order: the ground truth's distance travelled so far, and the frame's
  // position and rotation error after the ATE's alignment.
  std::vector<double> distance_m;
  std::vector<double> translation_error_m;
  std::vector<double> rotation_error_deg;
  std::vector<SegmentErrors> segments;  // one per segment length asked for
};

// Throws InvalidArgument when the lengths differ, fewer than 2 poses are given or a segment
// length is not positive.
TrajectoryErrors EvaluateTrajectory(const std::vector<Rigid3d>& estimate_world_from_rig,
                                    const std::vector<Rigid3d>& gt_world_from_rig,
                                    const std::vector<double>& segment_lengths_m = {1.0, 10.0});

// How far apart two calibrations of one camera image the same bearings: the RMS, over a
// 4-pixel grid in the annulus [min_radius_px, max_radius_px] around truth's principal point,
// of the distance between each pixel and the projection with `estimate` of the bearing
// `truth` lifts it to. Pixels that do not lift or project are skipped; 0 when none remain.
double CalibrationPixelRms(const UnifiedIntrinsics& truth, const UnifiedIntrinsics& estimate,
                           double min_radius_px, double max_radius_px);

}  // namespace omnirig::slam
