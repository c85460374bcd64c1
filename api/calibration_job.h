#pragma once
// The `calibration` job type: its parameters, its result JSON, and its registration. The CLI
// (`omnirig calibrate`) builds the same request and returns the same JSON.
//
// params: {"board": {"type": "checkerboard" | "charuco", "cols", "rows" (inner corners),
//                    "square_size_mm", "marker_size_mm" and "aruco_dictionary" (charuco)}
//                   or {"type": "aprilgrid", "tag_cols", "tag_rows", "tag_size_m", "tag_spacing"}
//                   or "NAME.yaml" (a Kalibr target file of the dataset; api/board_json.h),
//          "options": {"fix": [names], "free": [names], "huber_loss_px", "outlier_sigmas",
//                      "min_outlier_px", "max_rejection_rounds", "max_view_rms_px",
//                      "min_corners_per_view", "min_views", "max_num_iterations",
//                      "principal_point_px": [u, v], "rim_circle_px": [u, v, r],
//                      "refine_subpixel", "try_enhanced", "allow_exhaustive", "redetect",
//                      "overlay_error_scale"},
//          "hints": {"IMAGE_NAME": [[u, v] x 4]},
//          "svp": {"mirror": {"rim_radius_mm", "rim_height_mm"}, "image", "search_margin_px",
//                  "num_profiles", "inlier_px"},
//          "camera": "cam0" | "cam1",
//          "recording": NAME, "topic": T, "start_s", "end_s", "frame_step"
//                  (frames of a recording's topic instead of images: api/recording_input.h)}
//          (all but "board" optional; "svp" runs the
//          single-viewpoint check, {} to find the rim without the mirror's dimensions)
// result: {"camera": {"model", "image_size", "intrinsics", "intrinsics_std"}, "rms_px",
//          "mean_px", "std_px", "rms_all_px", "error_definitions", "num_views_used",
//          "images": [{"name", "used", "reason", "rms_px", "cam_from_board", "num_corners",
//                      "num_inliers", "detector", "overlay", "corners_px", "corner_ids"}],
//          "solver": {...}, "timings_s": {...},
//          "svp": {"image", "found", "reason", "predicted_circle_px", "found_circle_px",
//                  "centre_offset_px", "radius_offset_px", "principal_point_px",
//                  "principal_point_offset_px", "num_edge_points", "overlay"}}  (when asked),
//          "exports": {"opencv_omnidir", "kalibr", "warnings"} (see WriteCameraExports),
//          "input": {"kind": "recording", ...} (from a recording: see RecordingFramesJson),
//          "coverage": {...} (see WriteCoverageReport)}

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "api/job_types.h"
#include "engine/calib/board.h"
#include "engine/calib/calibrate.h"
#include "engine/calib/pipeline.h"

namespace omnirig::api {

struct CalibrationRequest {
  BoardSpec board;
  // "board": "NAME.yaml": the board is the dataset's Kalibr target file, read when the job runs.
  std::string kalibr_target_file;
  ImageCalibrationOptions options;
  // "camera": "cam0" or "cam1": calibrate that camera of a stereo dataset from its folder's
  // images only (cam0/..., cam1/...).
  std::optional<std::string> camera;
};

// Parses and validates job params; throws InvalidArgument naming the offending field (unknown
// fields and wrong types included).
CalibrationRequest CalibrationRequestFromJson(const nlohmann::json& params);

// The images one calibration uses: those of `camera`'s folder when it is given; otherwise all,
// unless they are of two cameras (cam0/ and cam1/ images), which would calibrate two cameras as
// one: that throws InvalidArgument asking for "camera".
std::vector<std::string> CalibrationImageNames(const std::optional<std::string>& camera,
                                               const std::vector<std::string>& image_names);

nlohmann::json CalibrationReportToJson(const CalibrationReport& report);

// The exports every calibration job writes into its output folder (they become artifacts):
// kCameraOpenCvFileName (OpenCV omnidir FileStorage: camera_matrix K, distortion_coefficients D
// = (k1, k2, p1, p2), xi, image_width, image_height) and kCameraKalibrFileName (Kalibr
// camera_model omni, distortion_model radtan, intrinsics [xi, fu, fv, pu, pv]). Returns
// {"opencv_omnidir": NAME, "kalibr": NAME, "warnings": [what the formats drop]}, the result's
// "exports".
inline constexpr const char* kCameraOpenCvFileName = "camera_opencv.yaml";
inline constexpr const char* kCameraKalibrFileName = "camera_kalibr.yaml";
// `rostopic`: the recording's topic the images came from, written into the Kalibr export as
// Kalibr writes it ("rostopic"); none when empty.
nlohmann::json WriteCameraExports(const CameraModel& camera, const std::filesystem::path& dir,
                                  const std::string& rostopic = "");

// The report of what to do next (engine/calib/coverage.h) for a calibration of the images
// `read` reads: writes kCoverageImageFileName and, when the covariance allows,
// kUncertaintyImageFileName into `dir`, and returns the result's "coverage": {"image",
// "disk_centre_px", "disk_radius_px", "disk_from", "near_px", "covered_fraction",
// "uncertainty_image", "max_uncertainty_px", "median_uncertainty_px" (null when singular),
// "advice": [sentences]}.
inline constexpr const char* kCoverageImageFileName = "coverage.png";
inline constexpr const char* kUncertaintyImageFileName = "uncertainty.png";
nlohmann::json WriteCoverageReport(const CalibrationReport& report, const BoardSpec& board,
                                   const ImageReader& read, const std::filesystem::path& dir);

// The export every relative_pose job writes: kCamchainKalibrFileName, a Kalibr camchain of both
// cameras with cam1's T_cn_cnm1 = cam1_from_cam0, and each camera's "rostopic" when `rostopics`
// gives it (a rig from a recording). Returns {"kalibr_camchain": NAME, "warnings"}.
inline constexpr const char* kCamchainKalibrFileName = "camchain_kalibr.yaml";
nlohmann::json WriteRigExports(const StereoRig& rig, const std::filesystem::path& dir,
                               const std::array<std::string, 2>& rostopics = {});

// The job type (its validation, references and run), for JobTypes::Add.
JobType CalibrationJobType();

}  // namespace omnirig::api
