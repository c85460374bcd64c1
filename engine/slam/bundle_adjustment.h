#pragma once
// Bundle adjustment of the stereo rig as one device (the paper's eqs. 19-23): the residuals are
// the reprojection errors (pixels) of every landmark in both cameras of every rig pose that
// sees it, cam1 reached through the fixed cam0_from_cam1 (eq. 20). Parameters are rig poses
// (rig_from_world, one 7-double block each) and landmark positions; the calibration is fixed,
// or optionally refined (BundleAdjustWithCalibration, used by the global adjustment). Points are
// eliminated first (Schur complement), DENSE_SCHUR or SPARSE_SCHUR chosen by the number of free
// poses.

#include <array>
#include <string>
#include <vector>

#include <ceres/ceres.h>

#include "engine/geometry/camera_model.h"
#include "engine/slam/map.h"
#include "engine/util/progress.h"
#include "engine/util/solver_summary.h"

namespace omnirig::slam {

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
  int num_residuals = 0;        // 2 per observation
  double initial_rms_px = 0.0;  // before the first solve, over every observation used
  double final_rms_px = 0.0;    // after pruning and the final solve, over the inliers
  int num_observations_pruned = 0;
  int num_points_pruned = 0;
  std::string linear_solver;
  // Over both solves (the second without the pruned outliers) when there are two; time_s
  // includes the RMS and pruning passes.
  SolverSummary solver;
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

// BundleAdjust() over `landmark_ids` only (the landmarks the free frames observe, which the
// caller knows): a local adjustment then costs what its window holds, not what the map holds.
BundleAdjustmentReport BundleAdjustLandmarks(const StereoRig& rig,
                                             const std::vector<int>& free_frames,
                                             const std::vector<int>& landmark_ids,
                                             const BundleAdjustmentOptions& options, SlamMap* map,
                                             const ProgressSink& progress = ProgressSink());

// What an adjustment refines of the calibration besides poses and points.
enum class CalibrationRefinement { kNone, kIntrinsics, kRig, kAll };
// "none", "intrinsics", "rig", "all".
const char* CalibrationRefinementName(CalibrationRefinement refine);

struct CalibrationRefinementOptions {
  CalibrationRefinement refine = CalibrationRefinement::kNone;
  // Intrinsics held at their given values when the intrinsics are refined (both cameras),
  // indexed like UnifiedIntrinsics::params. Free by default: gamma_u, gamma_v, u0, v0. Held:
  // skew and k5 as calibration holds them; xi, which trades off against gamma and k1 along a
  // valley that even a calibration board pins down only loosely; and the distortion k1..k4,
  // which a scene spanning a band of elevations trades against the focal length (on
  // calibration_refinement_test's renders, freeing k1, k2 from the true calibration moved
  // gamma by -0.85 % and k1 by +0.014, 0.53 px RMS over the mirror; held, 0.25 px).
  std::array<bool, UnifiedIntrinsics::kNumParams> fixed_intrinsics{};
  // The rig refinement frees cam0_from_cam1's rotation only. Its translation stays: the
  // length is the reconstruction's only metric scale (scaling the baseline, the points and the
  // trajectory together changes no residual), and the direction is barely observable: 1 mm
  // sideways on the 100 mm baseline moves a point 3 m away by 0.3 mrad, as a rotation of
  // 0.3 mrad moves every point (on the synthetic scene of bundle_adjustment_test the direction
  // drifted from 0.57 to 0.77 degrees off when freed, trading against the rotation).
  // Refinement is refused (the adjustment runs with the calibration fixed, the report says
  // why) below these: rig positions, and observations per camera of adjusted landmarks.
  int min_frames = 5;
  int min_observations_per_camera = 500;

  CalibrationRefinementOptions() {
    for (int i : {UnifiedIntrinsics::kXi, UnifiedIntrinsics::kAlpha, UnifiedIntrinsics::kK1,
                  UnifiedIntrinsics::kK2, UnifiedIntrinsics::kK3, UnifiedIntrinsics::kK4,
                  UnifiedIntrinsics::kK5}) {
      fixed_intrinsics[i] = true;
    }
  }
  bool RefinesIntrinsics() const {
    return refine == CalibrationRefinement::kIntrinsics || refine == CalibrationRefinement::kAll;
  }
  bool RefinesRig() const {
    return refine == CalibrationRefinement::kRig || refine == CalibrationRefinement::kAll;
  }
  void Check() const;
};

struct CalibrationRefinementReport {
  CalibrationRefinement refine = CalibrationRefinement::kNone;
  bool applied = false;
  std::string reason;  // why not, when not applied
  // Names of the refined parameters: "cam0.gamma_u", ..., "cam0_from_cam1.rotation".
  std::vector<std::string> free_parameters;
  StereoRig before;
  StereoRig after;  // == before when not applied
  int num_frames = 0;
  int num_observations[2] = {0, 0};  // per camera, of the adjusted landmarks
};

// BundleAdjust() with the calibration refined as `refinement` says, when the problem is large
// enough (else, with the reason in `calibration`, the calibration stays fixed). Writes the
// refined calibration into `rig`; the pruning uses it.
BundleAdjustmentReport BundleAdjustWithCalibration(
    const CalibrationRefinementOptions& refinement, const std::vector<int>& free_frames,
    const BundleAdjustmentOptions& options, StereoRig* rig, SlamMap* map,
    CalibrationRefinementReport* calibration, const ProgressSink& progress = ProgressSink());

// Pose-only refinement of one frame against fixed landmarks (motion-only bundle adjustment):
// `observations[i]` measures `points_in_world[i]`. Returns the refined rig_from_world and
// writes per-observation inlier flags (final error under max_reprojection_error_px).
Rigid3d RefineRigPose(const StereoRig& rig, const Rigid3d& rig_from_world_init,
                      const std::vector<Observation>& observations,
                      const std::vector<Eigen::Vector3d>& points_in_world,
                      const BundleAdjustmentOptions& options, std::vector<bool>* inliers);

}  // namespace omnirig::slam
