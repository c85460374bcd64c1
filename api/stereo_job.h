#pragma once
// The `stereo_reconstruct` job type ("instant 3D" from stereo pairs of a calibrated rig,
// engine/stereo/stereo_reconstruct.h) and the epipolar curves the web page draws.
//
// Dataset: images named cam0/NAME and cam1/NAME, paired by NAME (one or more pairs).
// Params (unknown fields, and fields of the other method, are refused):
//   {"rig": JOB_ID,                      a succeeded relative_pose job
//    "trajectory": JOB_ID,               optional: a succeeded slam job placing the pairs
//    "method": "dense" | "sparse",       default "dense"
//    dense (engine/dense/dense_stereo.h, DenseStereoOptions; "grid_step_rad" is grid.step_rad):
//    "grid_step_rad", "max_parallax_deg", "block_size": int, "uniqueness_ratio": int,
//    "speckle_window_cells": int, "speckle_range_cells": int, "left_right_max_diff_cells": int,
//    "confidence_window_cells": int, "image_noise_grey", "min_confidence",
//    "disparity_std_cells", "max_relative_range_std", "dark_level", "mask_margin_cells": int,
//    "max_epipolar_offset_cells"
//    sparse (engine/stereo/stereo_reconstruct.h, StereoReconstructOptions):
//    "max_features": int, "ratio_test", "max_epipolar_error_rad", "mutual_check": bool,
//    "min_parallax_rad", "max_reprojection_error_rad", "keypoint_std_px",
//    "max_relative_range_std", "dark_level", "mask_margin_px": int}   (all optional)
// Result:
//   {"rig": JOB_ID, "method", "num_points": N, "artifact": "cloud.ply", "options": {...},
//    "pairs": [...], "warning" (dense: when some pairs gave few confident pixels),
//    "clouds_merged": bool (several pairs or a trajectory),
//    "trajectory": {"source": "slam job ID" | "NAME.tum", "num_pairs_placed", "warning"}
//    (with a trajectory),
//    "grid": {"rows", "cols", "step_rad", "num_disparities"} (dense)}
//   sparse pair: {"name", "num_keypoints": [cam0, cam1], "num_candidates", "num_matches",
//                 "num_points", "rejected": {"parallax", "reprojection", "uncertain"},
//                 "median_range_m", "median_range_std_m", "artifact"}
//   dense pair:  {"name", "num_mirror_cells", "num_matched_cells", "num_points",
//                 "confident_fraction", "mean_confidence", "median_range_m",
//                 "median_range_std_m", "epipolar_offset_cells", "num_epipolar_samples",
//                 "confidence_scale" (the pair-level fit check, DensePairResult),
//                 "range_tiff", "range_png", "artifact", "warning" (the images do not fit
//                 the rig, or fewer than half the mirror cells confident: dark, blurred or
//                 out-of-sync images)}
// Artifacts: one pair: cloud.ply (binary little-endian PLY, float x y z in metres in the pair's
// cam0 frame, uchar red green blue, and for dense float confidence). More than one pair:
// cloud_NAME.ply per pair (NAME with '/' and '.' replaced by '_'), each in its own cam0 frame.
// Or a robot recording's two image topics, paired by header stamp (params "recording",
// "topics", "start_s", "end_s", "frame_step", "pair_tolerance_s": api/recording_input.h).
// With a trajectory (params "trajectory", or the dataset's one .tum file: by timestamp when the
// pairs are named by time, else one pose per pair in order), cloud_NAME.ply per pair as well and
// cloud.ply holding every placed pair in the trajectory's world ("artifact" is cloud.ply,
// "clouds_merged" true, each pair says whether it was "placed"). Without one, no merged
// cloud.ply for several pairs (the pairs of a moving rig do not share a frame): "artifact" names
// the first pair's cloud and "clouds_merged" is false. Dense also writes per pair
// NAME_range.tiff (32-bit float metres from cam0's centre, 0 where unknown; columns = azimuth
// over 360 degrees, rows = angle from the baseline, row 0 the largest) and NAME_range.png (a
// coloured preview), NAME being the pair's name without extension.

#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "api/job_types.h"
#include "engine/dense/dense_stereo.h"
#include "engine/stereo/stereo_reconstruct.h"

namespace omnirig::api {

struct StereoReconstructParams {
  std::string rig_job;
  // A succeeded slam job whose trajectory places the pairs (frames named as the pairs).
  std::optional<std::string> trajectory_job;
  std::string method = "dense";       // "dense" (engine/dense) or "sparse" (SIFT features)
  StereoReconstructOptions options;   // method "sparse"
  dense::DenseStereoOptions dense;    // method "dense"
};

// Throws InvalidArgument naming the field for unknown fields, wrong types, invalid values.
StereoReconstructParams StereoReconstructParamsFromJson(const nlohmann::json& params);
nlohmann::json StereoReconstructOptionsToJson(const StereoReconstructOptions& options);
nlohmann::json DenseStereoOptionsToJson(const dense::DenseStereoOptions& options);

// Runs the job. Throws InvalidArgument for bad input (rig job without a rig, images without a
// partner, image sizes that differ from the rig's), Cancelled on cancellation.
nlohmann::json RunStereoReconstructJob(const nlohmann::json& params, const JobContext& context);

// JobType::check_inputs of the jobs that read a rig named by params "rig" (stereo_reconstruct,
// slam): every cam0/NAME and cam1/NAME image must have the size that camera was calibrated
// for. Throws InvalidArgument naming the first few that do not. A rig result that does not
// parse is left to the job, which reports it when it runs.
void CheckImagesFitRig(const nlohmann::json& params, const SubmissionInputs& inputs);

// The job type (its validation, references and run), for JobTypes::Add.
JobType StereoReconstructJobType();

// The epipolar curve of pixel (u, v) of camera `from_camera` (0 or 1) in the other camera, for
// the rig of a relative_pose result (GET /api/v1/jobs/{id}/epipolar?from=cam0&u=U&v=V):
//   {"from": "cam0", "to": "cam1", "pixel": [u, v], "polylines": [[[u, v], ...], ...]}
// polylines is empty when the pixel does not lift. Throws InvalidArgument for a result that
// holds no rig, from_camera not 0 or 1, or a non-finite pixel.
nlohmann::json EpipolarCurveJson(const nlohmann::json& relative_pose_result, int from_camera,
                                 double u, double v);

}  // namespace omnirig::api
