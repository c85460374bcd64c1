#pragma once
// Which intrinsics the stereo rig's joint refinement may free, chosen from the data by
// cross-validation of the rig itself.
//
// The rig pose and the cameras' intrinsics trade off: on the real fisheye pairs of bench_relpose
// freeing the tangential terms (k3, k4) with the rig moves the baseline by 0.3 to 0.4 mm at
// almost the same RMS, and keeping every intrinsic at its per-camera calibration moves it by
// about another millimetre. The fit's own RMS cannot choose (the freer model always fits better), so each
// candidate model is judged by how well it predicts pairs it has not seen: fit the rig on the
// other pairs, then for the held-out pair fit the board's pose from one camera's corners alone
// (cameras fixed), map it through cam0_from_cam1 into the other camera and measure that
// camera's reprojection error, both ways round. What a candidate predicts is exactly what the
// rig is for: where a point seen by one camera appears in the other.

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "engine/calib/board.h"
#include "engine/geometry/camera_model.h"
#include "engine/rig/relative_pose.h"
#include "engine/util/progress.h"

namespace omnirig {

// One model of the cameras for the rig: the intrinsics held fixed when each camera is
// calibrated alone, and whether / which the joint refinement frees.
struct RigIntrinsicsModel {
  using FixedSet = std::array<bool, UnifiedIntrinsics::kNumParams>;
  std::string name;
  FixedSet calibration_fixed{};
  bool refine_intrinsics = false;
  FixedSet joint_fixed{};
  // cam1's sets when they differ from cam0's (the two above then hold cam0's).
  std::optional<FixedSet> cam1_calibration_fixed;
  std::optional<FixedSet> cam1_joint_fixed;

  const FixedSet& CalibrationFixed(int camera) const {
    return camera == 1 && cam1_calibration_fixed ? *cam1_calibration_fixed : calibration_fixed;
  }
  const FixedSet& JointFixed(int camera) const {
    return camera == 1 && cam1_joint_fixed ? *cam1_joint_fixed : joint_fixed;
  }
  // Intrinsics the joint refinement estimates, both cameras together (0 when not refined).
  int NumFreeIntrinsics() const;
};

// The standard candidates, simplest first, from the fixed set `base` (skew and k5 by default):
//   "fixed"            each camera's own calibration, intrinsics not refined with the rig;
//   "tangential_fixed" k3 = k4 = 0 in the calibrations and the joint refinement, the rest of
//                      `base`'s free intrinsics refined with the rig;
//   "free"             every intrinsic free in `base` refined with the rig.
std::vector<RigIntrinsicsModel> StandardRigIntrinsicsModels(
    const std::array<bool, UnifiedIntrinsics::kNumParams>& base);

// Between "tangential_fixed" and "free", one camera's tangential terms only:
//   "tangential_free_cam0" k3, k4 free in cam0 (its calibration and the joint refinement),
//                          zero in cam1;
//   "tangential_free_cam1" the other way round.
std::vector<RigIntrinsicsModel> PerCameraTangentialModels(
    const std::array<bool, UnifiedIntrinsics::kNumParams>& base);

// The candidates of the relative_pose job's "intrinsics_model": "auto", simplest first: the
// standard ones with the per-camera tangential models between "tangential_fixed" and "free"
// (on the real fisheye pairs of bench_relpose the rule chose freeing cam0's tangential terms
// alone until the synchronisation test stopped dropping the "fixed" candidate's pairs for its
// calibration error; over the folds that leaves, it chooses "tangential_fixed"). Models that
// coincide with another for this `base` (tangential terms already fixed) are left out.
std::vector<RigIntrinsicsModel> AutoRigIntrinsicsModels(
    const std::array<bool, UnifiedIntrinsics::kNumParams>& base);

// A model with its per-camera calibrations (made by the caller with calibration_fixed).
struct RigModelCandidate {
  RigIntrinsicsModel model;
  CameraModel cam0, cam1;
};

struct RigModelScore {
  std::string name;
  int num_free_intrinsics = 0;
  RelativePoseReport fit;  // on all pairs (options: the base with the model's intrinsics)
  // Held-out prediction error over every fold, both directions (px, RMS of |e|); -1 when the
  // candidate could not be fitted.
  double cv_rms_px = -1.0;
  // Mean squared held-out error (px^2) above the best candidate's, and the standard error of
  // that difference from the folds' paired differences.
  double cv_excess_mse_px2 = 0.0;
  double cv_excess_se_px2 = 0.0;
  std::vector<double> fold_rms_px;  // per held-out pair, in `held_out` order
};

struct RigModelSelection {
  int chosen = -1;                    // into candidates; -1 when none could be fitted
  int lowest_error = -1;              // the candidate with the smallest cross-validation error
  std::string rule;                   // how `chosen` follows from the scores, in words
  std::vector<std::string> held_out;  // names of the pairs held out, one fold each
  std::vector<RigModelScore> candidates;
};

// Fits every candidate on all pairs with `options` (its refine_intrinsics and
// fixed_intrinsics replaced by the model's), then scores it by leave-one-pair-out prediction
// over the pairs every candidate used. Each fold restarts the joint refinement from the
// all-pairs solution without the held-out pair (same corner orders, same rejected pairs);
// the per-camera calibrations are not redone per fold, so the "fixed" model's intrinsics have seen
// one image of each held-out pair (a slight advantage to it).
// Choice (the one-standard-error rule of cross-validation): the simplest candidate (fewest
// free intrinsics) whose mean squared held-out error exceeds the lowest by no more than one
// standard error of the paired difference. options.num_threads fits candidates and folds side
// by side, one solver thread each: the result does not depend on it. Throws Cancelled through
// `progress`, whose callbacks are only ever called from one thread at a time.
RigModelSelection SelectRigIntrinsicsModel(const BoardSpec& board,
                                           const std::vector<StereoBoardPair>& pairs,
                                           const std::vector<RigModelCandidate>& candidates,
                                           const RelativePoseOptions& options,
                                           const ProgressSink& progress = {});

}  // namespace omnirig
