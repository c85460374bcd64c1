#pragma once
// The `relative_pose` job type: the metric pose between a stereo rig's two cameras from image
// pairs of a shared board (engine/rig/relative_pose.h).
//
// Dataset: images named cam0/NAME and cam1/NAME, paired by NAME; or a robot recording's two
// image topics, paired by header stamp (params "recording", "topics", "start_s", "end_s",
// "frame_step", "pair_tolerance_s": api/recording_input.h; the result's "input" says what was
// read, and the camchain export carries each camera's "rostopic").
// Params (unknown fields are refused):
//   {"board": {"type": "checkerboard" | "charuco", "cols", "rows", "square_size_mm",
//              "marker_size_mm", "aruco_dictionary"} | {"type": "aprilgrid", ...} | "NAME.yaml",
//                                                                 (api/board_json.h)
//    "calibrations": {"cam0": JOB_ID, "cam1": JOB_ID} | "NAME.yaml"  (optional: without it
//        both cameras are calibrated from their own images first; a name is a Kalibr camchain
//        of the dataset, omni-radtan, whose two cameras are taken as given calibrations
//        without views, its T_cn_cnm1 reported beside the estimate as `kalibr_camchain`)
//    "intrinsics_model": "auto" | "fixed" | "tangential_fixed" | "tangential_free_cam0" |
//                        "tangential_free_cam1" | "free"
//        (default "auto": each candidate model (each camera's own calibration kept; k3 = k4 = 0
//        and the rest refined with the rig; the same with one camera's k3, k4 free,
//        "tangential_free_cam0" / "_cam1"; every intrinsic but alpha and k5 refined with the
//        rig) is scored by leave-one-pair-out prediction of one camera's corners from the
//        other's, and the simplest within one standard error of the best is used. With given
//        calibrations the candidates are "fixed" (each calibration kept) and "free", where the
//        calibrations' own used views (their result's "images": corners, ids) join the pairs
//        in the joint fit as single-camera views, a camera chain in the manner of Kalibr; a
//        view that is one of the pairs' own images is not counted twice. All but "auto",
//        "fixed" and "free" need the job's own calibrations; engine/rig/pipeline.h),
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

#include <nlohmann/json.hpp>

#include "api/job_types.h"
#include "engine/calib/board.h"
#include "engine/rig/pipeline.h"
#include "engine/rig/relative_pose.h"

namespace omnirig::api {

struct RelativePoseParams {
  BoardSpec board;
  std::string kalibr_target_file;  // "board": "NAME.yaml", read when the job runs
  std::optional<std::string> cam0_calibration_job;  // both or neither
  std::optional<std::string> cam1_calibration_job;
  std::string kalibr_camchain_file;  // "calibrations": "NAME.yaml", read when the job runs
  RigFromImagesOptions options;  // intrinsics_model and the fit's tunables
};

// Throws InvalidArgument naming the field for unknown fields, wrong types, invalid values.
RelativePoseParams RelativePoseParamsFromJson(const nlohmann::json& params);

// The result JSON. camera0/camera1: the `camera` objects to report (the calibration results'
// own, so that their extra keys such as intrinsics_std survive); replaced by the refined
// cameras when the intrinsics were refined.
nlohmann::json RelativePoseResultToJson(const RelativePoseReport& report,
                                        const nlohmann::json& camera0,
                                        const nlohmann::json& camera1, bool intrinsics_refined);

// Runs the job: loads the given calibrations, then EstimateRigFromImages over the dataset's
// pairs (engine/rig/pipeline.h). Throws InvalidArgument for bad input (before any detection
// where it can) and when no rig can be estimated (too few pairs, degenerate geometry),
// Cancelled on cancellation.
nlohmann::json RunRelativePoseJob(const nlohmann::json& params, const JobContext& context);

// The job type (its validation, references and run), for JobTypes::Add.
JobType RelativePoseJobType();

}  // namespace omnirig::api
