#pragma once
// The `relative_pose` job type: the metric pose between a stereo rig's two cameras from image
// pairs of a shared board (engine/rig/relative_pose.h).
//
// Dataset: images named cam0/NAME and cam1/NAME, paired by NAME.
// Params (unknown fields are refused):
//   {"board": {"type": "checkerboard" | "charuco", "cols", "rows", "square_size_mm",
//              "marker_size_mm", "aruco_dictionary"},             (api/calibration_job.h)
//    "calibrations": {"cam0": JOB_ID, "cam1": JOB_ID},            (optional: without it both
//                                                                  cameras are calibrated from
//                                                                  their own images first)
//    "refine_intrinsics": bool (default: true when the job calibrates the cameras itself, false
//                               with given calibrations),
//    "fixed_intrinsics": [names] (held fixed in the job's own calibrations and the joint
//                                 refinement: UnifiedIntrinsics names or "skew", "tangential",
//                                 "principal_point", "gamma"; default ["alpha", "k5"]; e.g.
//                                 ["alpha", "k5", "tangential"] for a fisheye lens, whose
//                                 tangential terms trade against the rig pose),
//    "intrinsics_model": "auto" | "fixed" | "tangential_fixed" | "tangential_free_cam0" |
//                        "tangential_free_cam1" | "free"
//        (default "auto" when neither refine_intrinsics nor fixed_intrinsics is given: each
//        candidate model (each camera's
//        own calibration kept; k3 = k4 = 0 and the rest refined with the rig; the same with one
//        camera's k3, k4 free, "tangential_free_cam0" / "_cam1"; everything but
//        fixed_intrinsics refined with the rig) is scored by leave-one-pair-out prediction of
//        one camera's corners from the other's, and the simplest within one standard error of
//        the best is used. fixed_intrinsics is then the models' common fixed set. With
//        given calibrations the candidates are "fixed" (today's behaviour, also by name) and
//        "free", where the calibrations' own used views (their result's "images": corners,
//        ids) join the pairs in the joint fit as single-camera views, a camera chain in the
//        manner of Kalibr; a view that is one of the pairs' own images is not counted twice.
//        Not with refine_intrinsics; all but "auto", "fixed" and "free" need the job's own
//        calibrations),
//    "resolve_corner_order": bool, "huber_loss_px": number, "max_num_iterations": int,
//    "sync_false_alarm_rate": number in [0, 1) (default 0.01: the probability that a set of
//        simultaneous pairs loses one to the synchronisation test, engine/rig/relpose_sync.h;
//        0 turns the test off)}
// Result:
//   {"cam0_from_cam1": {"rotation_wxyz", "translation_m"}, "baseline_m", "baseline_std_m",
//    "translation_std_m", "rotation_std_deg", "rms_px",
//    "pairs": [{"name", "used", "reason", "rms_px", "num_corners", "cam1_corner_order",
//               "cam0_from_board", "sync_statistic", "board_offset_m", "board_rotation_deg"}],
//              (sync_statistic: the synchronisation test's statistic, compared with
//               sync_test.limit; board_offset_m / _deg: the two cameras' own board poses
//               compared through the rig at the board's centre; null where not tested)
//    "cameras": {"cam0": camera, "cam1": camera},  (the calibration results' `camera` objects,
//                                                   or the refined ones)
//    "linear_cam0_from_cam1", "averaged_cam0_from_cam1", "num_pairs_used",
//    "spread_eigen_ratio", "calibrations": {...}, "solver": {...},
//    "sync_test": {"run", "corner_noise_px": [cam0, cam1], "dispersion", "median_statistic",
//                  "limit", "num_pairs_left_out"},
//    "observations": {"pairs_given", "pairs_used", "single_camera_views_given",
//                     "single_camera_views_used"},
//    "single_camera_views": [{"name", "camera", "used", "reason", "rms_px", "num_corners"}],
//    "intrinsics_model": {"chosen", "selection": "cross_validation" | "given", "rule",
//                         "held_out_pairs", "candidates": [{"name", "num_free_intrinsics",
//                         "baseline_m", "rms_px", "num_pairs_used", "cv_rms_px",
//                         "cv_excess_mse_px2", "cv_excess_se_px2"}]}}  (candidates: auto only)

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "api/job_types.h"
#include "engine/calib/board.h"
#include "engine/rig/relative_pose.h"
#include "engine/rig/relpose_model_select.h"

namespace omnirig::api {

struct RelativePoseParams {
  BoardSpec board;
  std::optional<std::string> cam0_calibration_job;  // both or neither
  std::optional<std::string> cam1_calibration_job;
  // "auto" (choose by cross-validation, engine/rig/relpose_model_select.h), one of the
  // candidate models "fixed", "tangential_fixed", "tangential_free_cam0",
  // "tangential_free_cam1", "free" (already applied to `options`), or ""
  // when refine_intrinsics / fixed_intrinsics were given without it.
  std::string intrinsics_model;
  // The fixed set the models start from (params.fixed_intrinsics, default skew and k5).
  std::array<bool, UnifiedIntrinsics::kNumParams> base_fixed_intrinsics{};
  RelativePoseOptions options;
};

// Throws InvalidArgument naming the field for unknown fields, wrong types, invalid values.
RelativePoseParams RelativePoseParamsFromJson(const nlohmann::json& params);

struct ImagePairNames {
  std::string name;  // NAME
  std::string cam0;  // "cam0/NAME"
  std::string cam1;  // "cam1/NAME"
};

// Pairs a dataset's images by NAME. Throws InvalidArgument listing images without a partner,
// and when there are no cam0/ or cam1/ images at all. Other images are ignored.
std::vector<ImagePairNames> MatchImagePairs(const std::vector<std::string>& image_names);
// NAME read as a number, as datasets often name frames by their time ("1403636579.763.png"),
// or "t" and a number as recordings do ("t000012.345.png", slam::FrameName); nullopt when it is
// not one.
std::optional<double> NameAsTimestamp(const std::string& name);

// The result JSON. camera0/camera1: the `camera` objects to report (the calibration results'
// own, so that their extra keys such as intrinsics_std survive); replaced by the refined
// cameras when the intrinsics were refined.
nlohmann::json RelativePoseResultToJson(const RelativePoseReport& report,
                                        const nlohmann::json& camera0,
                                        const nlohmann::json& camera1, bool intrinsics_refined);

// Runs the job: load or calibrate the cameras, read and check every image, detect, estimate.
// Throws InvalidArgument for bad input (before any detection where it can) and when no rig
// can be estimated (too few pairs, degenerate geometry), Cancelled on cancellation.
nlohmann::json RunRelativePoseJob(const nlohmann::json& params, const JobContext& context);

// Registers `relative_pose` with api/job_types.h.
void RegisterRelativePoseJobType();

}  // namespace omnirig::api
