#pragma once
// Metric relative pose of the two cameras of a stereo rig from a board both see at once
// (the paper's section 3.3), refined as one device (eq. 20).
//
// Pipeline, one function each (see relpose_linear.h, relpose_corner_order.h,
// relpose_refine.h):
//   1. the board's pose in each camera of each pair by pose-only least squares, model fixed;
//   2. the corner order of cam1 made consistent with cam0's: a detector cannot tell a
//      checkerboard from its half turn when the pattern is symmetric (and a square grid from its
//      quarter turns), so each pair's candidate orders are tried and the one that makes every
//      pair agree on one rig pose is kept;
//   3. the linear system of eq. (9) over all pairs' corners for R and t, R projected onto SO(3)
//      by SVD, t re-solved for that R;
//   4. a joint refinement of cam0_from_cam1 and every board pose (in cam0) minimising the
//      reprojection error in both images with a robust loss (optionally both cameras'
//      intrinsics too); the covariance of cam0_from_cam1 gives the baseline's and the
//      rotation's standard deviations;
//   5. the pair whose two images disagree most on the board's pose, if by more than the
//      corner noise explains (the board moved between two unsynchronised exposures;
//      relpose_sync.h), is left out and steps 3-4 run again, until no pair is flagged.
//
// Frames: cam0_from_cam1 maps points in cam1's frame into cam0's (eq. 8); the board frame is
// BoardSpec's (metres). Pixels: the centre of the top-left pixel is (0, 0).

#include <array>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "engine/calib/board.h"
#include "engine/calib/detect.h"
#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"
#include "engine/rig/relpose_refine.h"
#include "engine/rig/relpose_sync.h"
#include "engine/util/progress.h"

namespace omnirig {

// One image pair: the board as detected in cam0's and in cam1's image, taken at one instant.
// Or, with `single_camera_view`, one camera's image alone (a calibration view; the other
// detection is empty): it constrains that camera's intrinsics where the joint refinement frees
// them (a camera chain in the manner of Kalibr), never the rig itself, and is neither tested
// for synchronisation nor held out by the cross-validation.
struct StereoBoardPair {
  std::string name;
  BoardDetection cam0;
  BoardDetection cam1;
  bool single_camera_view = false;
};

struct RelativePoseOptions {
  // Try the other corner orders of cam1's detection that the board's symmetry allows (half
  // turn; quarter turns for square grids) and keep the one consistent across pairs. Only for
  // boards whose detections number corners by grid position (checkerboards); ChArUco ids are
  // unambiguous.
  bool resolve_corner_order = true;
  // Two pairs agree on the rig pose when their rotations differ by less than this...
  double consensus_rotation_deg = 5.0;
  // ...and their translations by less than this fraction of the board's distance from cam0.
  double consensus_translation_fraction = 0.1;
  // A board pose whose own fit leaves a larger RMS is not used (bad corners or a wrong model).
  double max_board_pose_rms_px = 5.0;
  // Refine both cameras' intrinsics with the rig...
  bool refine_intrinsics = false;
  // ...except these (UnifiedIntrinsics order), which keep the given cameras' values. Skew and
  // k5 by default, as in CalibrationOptions. On the real fisheye pairs (bench_relpose) freeing
  // k5 or skew moves the baseline by under 0.05 mm, but fixing the tangential terms (k3, k4)
  // moves it by +0.3 to +0.4 mm: they trade against the rig pose at almost the same RMS. Which set to
  // free can be chosen from the data by cross-validation (relpose_model_select.h, the
  // relative_pose job's default).
  std::array<bool, UnifiedIntrinsics::kNumParams> fixed_intrinsics = DefaultFixedIntrinsics();
  // cam1's fixed set when it differs from cam0's (`fixed_intrinsics` then holds cam0's).
  std::optional<std::array<bool, UnifiedIntrinsics::kNumParams>> cam1_fixed_intrinsics;
  // Pairs whose two images do not show one board pose (the board moved between two
  // unsynchronised exposures) are found by a statistical test against the corner noise and
  // left out, the rig refitted (relpose_sync.h states the rule).
  SyncTestOptions sync_test;
  // Huber loss scale on the pixel residuals of the joint refinement.
  double huber_loss_px = 1.0;
  int max_num_iterations = 100;
  int num_threads = 1;
  // At least this many pairs must survive to estimate the rig.
  int min_num_pairs = 2;
  // Degeneracy: the corners of all used pairs, in cam1's frame, must not be (nearly) coplanar,
  // or eq. (9) is rank-deficient and the rig rests on one board pose's depth and tilt. The
  // test: smallest / largest eigenvalue of their scatter matrix above this.
  double min_spread_eigen_ratio = 1e-3;

  // Throws InvalidArgument naming the offending field.
  void Check() const;
  // The joint refinement's options (eq. 20) that these imply.
  RigRefinementOptions RefinementOptions() const;
};

struct RelativePosePairReport {
  std::string name;
  bool used = false;
  std::string reason;          // why not used (empty when used)
  // Both images' corners after the joint refinement, one board pose through the rig; -1 if
  // unused.
  double rms_px = -1.0;
  int num_corners = 0;         // corners seen by both cameras
  int cam1_order = 0;          // 0: cam1's corner order as detected; k: the k-th symmetry
  int single_camera = -1;      // the camera of a single-camera view; -1 for a pair
  Rigid3d cam0_from_board;     // after refinement (used pairs), at cam0's exposure
  // The synchronisation test (relpose_sync.h) of the last round the pair took part in: its
  // statistic (compared with RelativePoseReport::sync_test.limit) and the two cameras' own
  // board poses compared through the rig at the board's centre. -1 when not tested.
  double sync_statistic = -1.0;
  double board_offset_m = -1.0;
  double board_rotation_deg = -1.0;
};

struct RelativePoseReport {
  // False when no rig could be estimated; `message` says why (too few pairs, degenerate
  // geometry). Per-pair reasons are in `pairs` either way.
  bool success = false;
  std::string message;

  StereoRig rig;  // cameras (refined when asked) and cam0_from_cam1
  double baseline_m = 0.0;
  // Along the baseline direction, from the covariance.
  double baseline_std_m = 0.0;
  Eigen::Vector3d translation_std_m = Eigen::Vector3d::Zero();
  double rotation_std_deg = 0.0;      // RMS angle of the rotation's uncertainty
  // The same from the cluster-robust covariance over pairs (RigUncertainty in relpose_refine.h):
  // honest when the pairs disagree beyond their corner noise, as on the real fisheye pairs of
  // bench_relpose, where baseline_std_m is ~8 times below the leave-one-pair-out spread. -1
  // when it could not be computed (fewer than 3 pairs).
  double baseline_std_robust_m = -1.0;
  double rotation_std_robust_deg = -1.0;
  double rms_px = 0.0;                // all used corners of both cameras

  // The steps before the joint refinement, kept for comparison: eq. (9) with the SVD
  // projection, and the average of the per-pair poses.
  Rigid3d linear_cam0_from_cam1;
  Rigid3d averaged_cam0_from_cam1;

  bool degenerate = false;
  double spread_eigen_ratio = 0.0;
  int num_pairs_used = 0;               // pairs, not single-camera views
  int num_single_camera_views_used = 0;  // used only with refine_intrinsics
  // The synchronisation test on the final rig's pairs (its per-pair entries are copied into
  // `pairs`), and how many rounds of test, rejection of one pair and refit ran (the number of
  // pairs it left out).
  SyncTestReport sync_test;
  int sync_rounds = 0;
  SolverSummary solver;
  std::vector<RelativePosePairReport> pairs;
};

// Estimates the rig from board pairs with both cameras' models known. Never throws for an
// expected outcome (a pair without the board, disagreeing pairs, degenerate geometry): those
// are in the report. Throws InvalidArgument for invalid options or board, Cancelled through
// `progress`.
// One line for a person: "baseline 100.02 +- 0.05 mm, rotation 0.21 deg, 18 of 20 pairs used"
// (the rotation is the angle of cam0_from_cam1's rotation). The job's last progress message.
std::string RelativePoseSummary(const RelativePoseReport& report);

RelativePoseReport EstimateRelativePose(const CameraModel& cam0, const CameraModel& cam1,
                                        const BoardSpec& board,
                                        const std::vector<StereoBoardPair>& pairs,
                                        const RelativePoseOptions& options,
                                        const ProgressSink& progress = {});

}  // namespace omnirig
