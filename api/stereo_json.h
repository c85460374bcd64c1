#pragma once
// The `stereo_reconstruct` job type ("instant 3D" from stereo pairs of a calibrated rig,
// engine/stereo/stereo_reconstruct.h) and the epipolar curves the web page draws.
//
// Dataset: images named cam0/NAME and cam1/NAME, paired by NAME (one or more pairs).
// Params (unknown fields are refused):
//   {"rig": JOB_ID,                      a succeeded relative_pose job
//    "max_features": int, "ratio_test", "max_epipolar_error_rad", "mutual_check": bool,
//    "min_parallax_rad", "max_reprojection_error_rad", "keypoint_std_px",
//    "max_relative_range_std", "dark_level", "mask_margin_px": int}   (all optional; the names
//                                        and meanings of StereoReconstructOptions)
// Result:
//   {"rig": JOB_ID, "num_points": N, "artifact": "cloud.ply",
//    "pairs": [{"name", "num_keypoints": [cam0, cam1], "num_candidates", "num_matches",
//               "num_points", "rejected": {"parallax", "reprojection", "uncertain"},
//               "median_range_m", "median_range_std_m", "artifact"}],
//    "options": {...}}
// Artifacts: one pair: cloud.ply (binary little-endian PLY, float x y z in metres in the pair's
// cam0 frame, uchar red green blue). More than one pair: cloud_NAME.ply per pair (NAME with
// '/' and '.' replaced by '_'), each in its own cam0 frame, and no merged cloud.ply (the pairs
// of a moving rig do not share a frame); "artifact" names the first pair's cloud and
// "clouds_merged" is false.

#include <string>

#include <nlohmann/json.hpp>

#include "api/job_types.h"
#include "engine/stereo/stereo_reconstruct.h"

namespace omnirig::api {

struct StereoReconstructParams {
  std::string rig_job;
  StereoReconstructOptions options;
};

// Throws InvalidArgument naming the field for unknown fields, wrong types, invalid values.
StereoReconstructParams StereoReconstructParamsFromJson(const nlohmann::json& params);
nlohmann::json StereoReconstructOptionsToJson(const StereoReconstructOptions& options);

// Runs the job. Throws InvalidArgument for bad input (rig job without a rig, images without a
// partner, image sizes that differ from the rig's), Cancelled on cancellation.
nlohmann::json RunStereoReconstructJob(const nlohmann::json& params, const JobContext& context);

// Registers `stereo_reconstruct` with api/job_types.h.
void RegisterStereoReconstructJobType();

// The epipolar curve of pixel (u, v) of camera `from_camera` (0 or 1) in the other camera, for
// the rig of a relative_pose result (GET /api/v1/jobs/{id}/epipolar?from=cam0&u=U&v=V):
//   {"from": "cam0", "to": "cam1", "pixel": [u, v], "polylines": [[[u, v], ...], ...]}
// polylines is empty when the pixel does not lift. Throws InvalidArgument for a result that
// holds no rig, from_camera not 0 or 1, or a non-finite pixel.
nlohmann::json EpipolarCurveJson(const nlohmann::json& relative_pose_result, int from_camera,
                                 double u, double v);

}  // namespace omnirig::api
