#pragma once
// Calibration of a catadioptric camera with Mei's unified model (the paper's section 3):
// detect -> initialise (closed form) -> build problem (eq. 7) -> solve -> reject outliers ->
// re-solve -> evaluate.

#include <array>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "engine/calib/board.h"
#include "engine/calib/detect.h"
#include "engine/calib/svp.h"
#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"
#include "engine/util/progress.h"
#include "engine/util/solver_summary.h"

namespace omnirig {

// One image's detection, by name.
struct CalibrationView {
  std::string name;
  BoardDetection detection;
};

struct CalibrationOptions {
  // Parameters held at their initial value, indexed like UnifiedIntrinsics::params. By default
  // skew and k5 are fixed at zero, so that exports to OpenCV omnidir and Kalibr are exact.
  std::array<bool, UnifiedIntrinsics::kNumParams> fixed{};
  // Initial principal point; when absent it comes from the mirror rim circle (if given) or the
  // image centre, whichever initialises better.
  std::optional<Eigen::Vector2d> principal_point_px;
  // Mirror rim circle in the image (centre u, v and radius, pixels), a better principal point.
  std::optional<Eigen::Vector3d> rim_circle_px;

  // Robust loss (Huber) scale on pixel residuals; 0 for plain least squares.
  double huber_loss_px = 1.0;
  // A corner whose error exceeds max(outlier_sigmas * robust std, min_outlier_px) after a solve
  // is rejected and the problem re-solved, at most max_rejection_rounds times; 0 turns
  // rejection (and the robust loss) off.
  double outlier_sigmas = 4.0;
  double min_outlier_px = 1.0;
  int max_rejection_rounds = 3;
  // A view whose RMS after rejection exceeds this (px) is dropped entirely.
  double max_view_rms_px = 5.0;
  // Views need this many corners to be used; a calibration needs this many views.
  int min_corners_per_view = 6;
  int min_views = 3;

  int max_num_iterations = 200;
  int num_threads = 1;

  CalibrationOptions() {
    fixed[UnifiedIntrinsics::kAlpha] = true;
    fixed[UnifiedIntrinsics::kK5] = true;
  }
  // Fixes or frees a parameter by its name in UnifiedIntrinsics::kNames, or the groups
  // "skew" (alpha), "tangential" (k3, k4), "principal_point" (u0, v0), "gamma" (both).
  // Throws InvalidArgument for an unknown name.
  void SetFixed(const std::string& name, bool fix);
  void Check() const;
};

struct CalibrationImageReport {
  std::string name;
  bool used = false;
  std::string reason;    // why not used (empty when used)
  std::string detector;  // BoardDetection::method
  double rms_px = 0.0;   // RMS of this view's inlier corner errors (px)
  Rigid3d cam_from_board;
  std::vector<Eigen::Vector2d> corners_px;      // detected
  std::vector<int> corner_ids;                  // into BoardSpec::ObjectPoints()
  std::vector<Eigen::Vector2d> reprojected_px;  // the model's prediction of each corner
  std::vector<bool> inlier;                     // false for corners rejected as outliers
};

// The solver summary of the calibration's rounds: num_iterations counts the Levenberg-Marquardt
// steps over every round (each round's iteration 0, the initial evaluation, not counted);
// initial_cost is the first round's, final_cost, termination and usable the last's, time_s
// the solve's wall clock (CalibrationTimings::solve_s).
struct CalibrationSolverSummary : SolverSummary {
  int num_rounds = 0;  // solves (1 + re-solves after rejection)
  int num_residuals = 0;
  int num_parameters = 0;
  int num_rejected_corners = 0;
  int num_rejected_views = 0;
  // One line in the shape of Ceres' BriefReport(), over every round (the counts above), so that
  // its "Iterations" agrees with `num_iterations`.
  std::string brief;
};

// Wall-clock seconds. detect_s and redetect_s are filled by CalibrateImages (reading the images
// and detecting the board, in parallel; the model-based second pass), the rest by Calibrate.
struct CalibrationTimings {
  double detect_s = 0.0;
  double redetect_s = 0.0;
  double init_s = 0.0;
  double solve_s = 0.0;
  double covariance_s = 0.0;
  double total_s = 0.0;
};

// What became of one image or frame of a calibration's input, in input order (CalibrateImages).
// reason: "used", "unreadable", "no_board" (the cheap test of a long input found no whole board),
// "near_duplicate_of" (duplicate_of names the kept frame whose board is where this one's is),
// "detection_failed", "not_selected" (detected, another view chosen for the mirror's and the
// poses' coverage), "outlier" (detected, left out by the calibration); detail says more where
// there is more (the detector's or the calibration's reason).
struct FrameReport {
  std::string name;
  bool used = false;
  std::string reason;
  std::string duplicate_of;
  std::string detail;
};

struct CalibrationReport {
  CameraModel camera;
  // Standard deviation of each intrinsic (UnifiedIntrinsics order) from the Ceres covariance
  // scaled by the residual variance; 0 for fixed parameters.
  std::array<double, UnifiedIntrinsics::kNumParams> intrinsics_std{};
  // Over every inlier corner of the used views: rms_px = sqrt(mean(|e|^2)); mean_px and std_px
  // are the mean and standard deviation of the Euclidean error |e| (px).
  double rms_px = 0.0;
  double mean_px = 0.0;
  double std_px = 0.0;
  // RMS over every corner of the used views, outliers included (px).
  double rms_all_px = 0.0;
  int num_views_used = 0;
  std::vector<CalibrationImageReport> images;  // in the order of the input views
  CalibrationSolverSummary solver;
  CalibrationTimings timings;
  // The single-viewpoint check that CalibrateImages runs on request (ImageCalibrationOptions::
  // svp), on the image named svp_image.
  std::optional<SvpCheckReport> svp;
  std::string svp_image;
  // Every image or frame given to CalibrateImages (images above holds only those detected fully
  // on a long input), and the cap on the views of a long input (0: the input was short enough
  // for every view to be detected and used).
  std::vector<FrameReport> frames;
  int max_views = 0;
};

// Calibrates a camera of `width` x `height` pixels from board detections. Views whose detection
// failed are reported as unused with the detection's reason. Throws InvalidArgument, listing
// each image's reason, when fewer than options.min_views views are usable; Cancelled when the
// sink cancels. Progress: stage "init", then "solve" per LM iteration.
CalibrationReport Calibrate(const std::vector<CalibrationView>& views, int width, int height,
                            const BoardSpec& board, const CalibrationOptions& options,
                            const ProgressSink& progress);

}  // namespace omnirig
