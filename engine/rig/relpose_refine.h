#pragma once
// The joint refinement of a stereo rig as one device (the paper's eq. 20 minimised as eq. 19):
// cam0_from_cam1 and one board pose per pair, optionally both cameras' intrinsics.

#include <array>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"
#include "engine/util/progress.h"
#include "engine/util/solver_summary.h"

namespace omnirig {

// The corners of one pair, with cam1's ids already made consistent with cam0's.
struct RigPairCorners {
  std::vector<Eigen::Vector3d> points_in_board0;  // cam0's corners in the board frame
  std::vector<Eigen::Vector2d> pixels0;
  std::vector<Eigen::Vector3d> points_in_board1;  // cam1's corners in the board frame
  std::vector<Eigen::Vector2d> pixels1;
};

// The board's centre in the board frame: the mean of both cameras' object points (zero when
// there are none). Where the synchronisation test compares poses.
Eigen::Vector3d RigPairBoardCentre(const RigPairCorners& pair);

// Skew (alpha) and k5 fixed, every other intrinsic free.
std::array<bool, UnifiedIntrinsics::kNumParams> DefaultFixedIntrinsics();

// cam1's corners go through cam0's board pose and the rig (eq. 20).
struct RigRefinementOptions {
  bool refine_intrinsics = false;
  // With refine_intrinsics: the intrinsics (UnifiedIntrinsics order) that stay constant...
  std::array<bool, UnifiedIntrinsics::kNumParams> fixed_intrinsics = DefaultFixedIntrinsics();
  // ...in cam1 these instead, when given (a model that frees a term in one camera only).
  std::optional<std::array<bool, UnifiedIntrinsics::kNumParams>> cam1_fixed_intrinsics;
  double huber_loss_px = 1.0;
  int max_num_iterations = 100;
  int num_threads = 1;
};

// The standard deviations of cam0_from_cam1 from the inverse of the Gauss-Newton Hessian,
// scaled by the residuals' variance (sum of squares / degrees of freedom).
struct RigUncertainty {
  bool valid = false;
  Eigen::Vector3d translation_std_m = Eigen::Vector3d::Zero();
  double baseline_std_m = 0.0;    // along cam0_from_cam1.translation's direction
  double rotation_std_deg = 0.0;  // RMS angle: sqrt(trace) of the rotation-vector covariance
  // The same two from the cluster-robust (sandwich) covariance over pairs,
  // H^-1 (sum_i g_i g_i^T) H^-1 N / (N - 1), g_i pair i's gradient of the cost: honest when the
  // pairs disagree by more than independent corner noise explains (e.g. a board that moved
  // between two unsynchronised exposures, or a model error each pose sees differently), where
  // the Gauss-Newton covariance above is far too small; noisier with few pairs. Valid with 3
  // pairs or more.
  bool robust_valid = false;
  double robust_baseline_std_m = 0.0;
  double robust_rotation_std_deg = 0.0;
};

// Refines `rig` (cam0_from_cam1, and intrinsics when asked) and `cam0_from_board` (one per
// pair) in place. Cancellable between solver iterations (throws Cancelled).
SolverSummary RefineRig(const std::vector<RigPairCorners>& pairs,
                        const RigRefinementOptions& options, StereoRig* rig,
                        std::vector<Rigid3d>* cam0_from_board, RigUncertainty* uncertainty,
                        const ProgressSink& progress = {});

// The uncertainty RefineRig reports, of a solution it returned (the same problem, evaluated at
// `rig` and `cam0_from_board`): for a caller that refits several times and needs only the last
// fit's.
RigUncertainty EstimateRigUncertainty(const std::vector<RigPairCorners>& pairs,
                                      const RigRefinementOptions& options, const StereoRig& rig,
                                      const std::vector<Rigid3d>& cam0_from_board);

// The board pose of one pair with the rig and both cameras held fixed: plain (not robust)
// least squares over both images' corners, each camera's residuals divided by its corner noise
// `noise_px` (per coordinate). `cam0_from_board` is the starting point and receives the
// solution. Returns the weighted sum of squares at the solution (dimensionless), or -1 when
// the solve fails or a corner does not project.
double FitBoardThroughRig(const StereoRig& rig, const RigPairCorners& pair,
                          const std::array<double, 2>& noise_px, Rigid3d* cam0_from_board);

// RMS (pixels) over one pair's corners in both images; a corner that does not project counts
// as a residual of 1e3 px (never silently dropped). cam1's board pose is the rig's prediction.
double PairRmsPx(const StereoRig& rig, const Rigid3d& cam0_from_board, const RigPairCorners& pair);

}  // namespace omnirig
