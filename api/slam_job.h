#pragma once
// The `slam` job type and the `omnirig slam` command: trajectory and metric map from a stereo
// sequence (engine/slam/slam.h).
//
// Dataset: images named cam0/NAME and cam1/NAME, paired by NAME and ordered by NAME; or a
// recording as videos (any container and codec OpenCV's FFmpeg back-end reads: .mp4 .m4v .mov
// .mkv .webm .avi): cam0.EXT and cam1.EXT, or one stacked.EXT holding cam0 on top of cam1 in
// every frame (engine/slam/video_source.h; frames paired by container timestamp, named
// "t000012.345" by it). Optionally a ground-truth trajectory (TUM format): for images one pose
// per image pair in the same order; for videos poses matched to the frames by timestamp.
// Or a robot recording's two image topics (api/recording_input.h, docs/recordings.md): frames
// paired by header stamp, named by cam0's ("t1700000000.050").
// Params (unknown fields are refused):
//   {"rig": JOB_ID,                 a succeeded relative_pose job (its cam0_from_cam1, cameras)
//    "ground_truth": "NAME.tum",    optional, a file of the dataset
//    "options": {...},              optional, see SlamOptionsFromJson
//    "dense_map": {"voxel_m": 0.02}, optional, see SlamParams::dense_map
//    "frame_step": 1,               optional, every n-th stereo frame (images or videos)
//    "start_s": 0, "end_s": 12.5,   optional, videos only: the time range (container time)
//    "pair_tolerance_s": 0.005,     optional, videos and recordings: pairing tolerance
//                                   (default a quarter of the frame period)
//    "recording": NAME, "topics": {"cam0": T0, "cam1": T1},   optional: read a recording
//                                   (start_s, end_s after cam0's first stamp)
//    "map": JOB_ID}                 optional, a succeeded slam job (batch or live) of the same
//                                   rig: every frame is localised in its saved map's world
//                                   (relocalisation against its keyframes, then tracking on its
//                                   landmarks); what it lacks is mapped and joined to it.
//                                   Refused at submission (422) when the job is not a succeeded
//                                   slam job, has no saved map or was made with another rig.
// Artifacts written to the output folder:
//   trajectory.json  {"world_frame", "frames": [{"name", "state", "reason", "timestamp_s",
//                     "linked", "keyframe", "in_map" (localised in the saved map of "map";
//                     false without one), "world_from_rig": {"rotation_wxyz",
//                     "translation_m"} | null}], "rig"}
//   slam_map.bin     the saved map (engine/slam/saved_map.h: "OMNIRIG-MAP\n", a format
//                    version, the keyframes with their features and the landmarks), which a
//                    later job's "map" loads; with "map", the map it loaded with what this run
//                    added
//   trajectory.tum   "timestamp tx ty tz qx qy qz qw" per frame with a pose (world_from_rig)
//   map.ply          binary little-endian: float x y z (m), uchar red green blue,
//                    int num_observations
//   report.json      the result below
//   dense_map.ply, occupancy.pgm, occupancy.yaml   with "dense_map" (float x y z, uchar red
//                    green blue, float confidence; ROS map_server map, occupied 0 free 254
//                    unknown 205)
// Result:
//   {"artifacts": {"trajectory_json", "trajectory_tum", "map_ply", "slam_map", "report_json"},
//    "saved_map": {"artifact": "slam_map.bin", "format_version", "num_keyframes",
//                  "num_landmarks", "rig_job", "localised_in": JOB_ID | null},
//    "localised_in_map_fraction": frames in_map / frames, with "map" (else null),
//    "input": {"kind": "images", "frame_step", "num_frames", "num_image_pairs"} |
//             {"kind": "recording", ... (see RecordingFramesJson), "timestamp_pass_s",
//              "timestamp_pass_cpu_s"} |
//             {"kind": "video_pair" | "stacked_video", "files", "codec", "fps", "frame_count",
//              "frame_size", "pair_tolerance_s", "frame_step", "num_frames",
//              "timestamp_pass_s", "timestamp_pass_cpu_s" (the pass that pairs timestamps)},
//    "num_frames", "num_tracked", "num_lost", "num_map_points", "frames_per_second",
//    "frames": [{"name", "state", "reason", "motion_source", "num_features": [cam0, cam1],
//                "num_stereo_points", "num_matches", "num_essential_inliers",
//                "num_scale_inliers", "num_tracked_landmarks", "num_new_landmarks",
//                "times_s": {...}, "local_bundle_adjustment": {...} | null,
//                "world_from_rig": pose | null}],
//    "timings_s": {"load", "detect", "stereo", "match", "motion", "map", "local_ba",
//                  "global_ba", "total"},            (wall clock)
//    "cpu_timings_s": {...},                          (same keys, CPU seconds)
//    "global_bundle_adjustment": {...} | null,
//    "calibration_refinement": null (not asked for) |
//        {"refine", "applied", "reason" (why not applied), "free_parameters": ["cam0.gamma_u",
//         ..., "cam0_from_cam1.rotation"], "num_frames", "num_observations": [cam0, cam1],
//         "reprojection_rms_px": {"initial", "final"} (the global adjustment's),
//         "before": rig, "after": rig (rig = the relative_pose result's cam0_from_cam1,
//         baseline_m, cameras), "change": {"cam0": {param: after - before}, "cam1": {...},
//         "cam0_from_cam1_rotation_deg"}},
//    "evaluation": {"ate_rmse_m", "ate_max_m", "rpe_translation_rmse_m",
//                   "rpe_rotation_rmse_deg", "final_drift_percent", "max_drift_percent",
//                   "path_length_m", "num_poses", "gt_from_estimate"}   (with a ground truth)}

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "api/job_types.h"
#include "engine/dense/dense_map.h"
#include "engine/geometry/camera_model.h"
#include "engine/slam/slam.h"
#include "engine/slam/video_source.h"

namespace omnirig::api {

// The "options" object: {"max_features", "contrast_threshold", "detection_scale",
// "max_epipolar_error_rad", "temporal_max_descriptor_ratio", "temporal_gate_rad",
// "essential_max_angular_error_rad", "local_window_frames", "local_max_iterations",
// "global_bundle_adjustment", "huber_scale_px", "max_reprojection_error_px", "min_features",
// "min_stereo_points", "min_matches", "min_tracked_landmarks", "seed", "refine_calibration",
// "fixed_intrinsics"}; every field optional.
//   "refine_calibration": what the global bundle adjustment refines of the rig's calibration:
//     "none" (default), "intrinsics" (both cameras'), "rig" (cam0_from_cam1's rotation; the
//     translation is the metric scale and stays), "all"; false/true mean "none"/"all".
//     Refused (the result says why, the calibration stays) below 5 tracked frames or 500
//     observations per camera.
//   "fixed_intrinsics": names held when refining the intrinsics (UnifiedIntrinsics names or
//     "skew", "tangential", "principal_point", "gamma"); default
//     ["xi", "alpha", "k1", "k2", "k3", "k4", "k5"], i.e. gamma_u, gamma_v, u0, v0 refined
//     (see slam::CalibrationRefinementOptions).
// Throws InvalidArgument naming the field (unknown, mistyped, or failing SlamOptions::Check).
slam::SlamOptions SlamOptionsFromJson(const nlohmann::json& options);
// The value of "options.refine_calibration" (also the CLI's --refine-calibration).
slam::CalibrationRefinement CalibrationRefinementFromJson(const nlohmann::json& value);

struct SlamParams {
  std::string rig_job;
  std::optional<std::string> ground_truth;  // a file name in the dataset
  slam::SlamOptions options;
  // "dense_map": {"voxel_m", "keyframe_spacing_m", "grid_step_factor", "occupancy_cell_m",
  // "obstacle_min_height_m", "obstacle_max_height_m"} (each optional; engine/dense/dense_map.h):
  // fuse the dense clouds of keyframes along the trajectory into dense_map.ply and write
  // occupancy.pgm + occupancy.yaml (ROS map_server); the result's "dense_map" reports it.
  std::optional<dense::DenseMapOptions> dense_map;
  // "frame_step", "start_s", "end_s", "pair_tolerance_s"; which of them were given (the time
  // fields are refused on an image dataset).
  slam::VideoFrameOptions frames;
  bool video_only_fields = false;
  std::optional<std::string> map_job;  // "map"
};

// Where a run's saved map comes from and goes: the rig job it is made with (a later run must
// use the same) and the saved map it localised in, if any.
struct SavedMapSource {
  std::string rig_job;
  std::optional<std::string> map_job;
};

// The artifact every succeeded slam job writes its saved map to.
inline constexpr char kSavedMapArtifact[] = "slam_map.bin";

// The saved map of job `map_job` (params "map"), read from its artifact through
// context.artifact_path. Throws InvalidArgument naming the job when it has none or the file is
// not a saved map this omnirig reads.
std::shared_ptr<const slam::SavedMap> LoadSavedMap(const JobContext& context,
                                                   const std::string& map_job);
SlamParams SlamParamsFromJson(const nlohmann::json& params);

// The dataset's videos when it holds a recording (see above): nullopt when it holds none.
// Throws InvalidArgument when it is ambiguous (two cam0 videos, a pair and a stacked video, or
// videos and cam0/ cam1/ images together).
std::optional<slam::StereoVideoFiles> FindStereoVideos(const std::filesystem::path& dataset_dir,
                                                       const std::vector<std::string>& names);

// The check at submission (JobType::check_inputs): the images have the rig's calibrated size,
// a video dataset's files open, pair (frame counts and rates) and have the rig's frame size,
// read from their headers; the video-only params are refused on images. Throws InvalidArgument with the reason.
void CheckSlamInputs(const nlohmann::json& params, const SubmissionInputs& dataset);
// The part of it a live job checks too: the saved map of params "map" (a succeeded slam job,
// found by the caller) exists and was made with params "rig". Throws InvalidArgument.
void CheckSlamMap(const nlohmann::json& params,
                  const std::function<nlohmann::json(const std::string&)>& load_result);

// Runs SLAM over a dataset of images or videos, writes the artifacts into output_dir and
// returns the result JSON. A ground truth (TUM file) is read and checked (one pose per frame)
// and a recording's timestamps are read and paired, before the first frame is processed.
// `frame_options` selects frames (frame_step for both; the rest for videos). `log` may be
// empty.
nlohmann::json RunSlamOnDataset(
    const StereoRig& rig, const std::filesystem::path& dataset_dir,
    const std::vector<std::string>& image_names, const slam::SlamOptions& options,
    const std::optional<std::filesystem::path>& ground_truth,
    const std::filesystem::path& output_dir, const ProgressSink& progress,
    const std::function<void(const std::string&)>& log,
    const std::optional<dense::DenseMapOptions>& dense_map = std::nullopt,
    const slam::VideoFrameOptions& frame_options = {}, const SavedMapSource& map_source = {});

// The end of a run, as RunSlamOnDataset ends one: the artifacts (trajectory, map, report and,
// with `dense_map`, the dense map and occupancy grid fused from the frames `load` reads) into
// output_dir; returns the result JSON. `timestamps_s` per frame; `ground_truth` one pose per
// frame or empty; `input` is the result's "input".
nlohmann::json WriteSlamReport(const StereoRig& rig, const slam::SlamResult& result,
                               const std::vector<double>& timestamps_s,
                               const std::vector<slam::StampedPose>& ground_truth,
                               const nlohmann::json& input, const slam::StereoFrameLoader& load,
                               const std::optional<dense::DenseMapOptions>& dense_map,
                               int num_threads, const std::filesystem::path& output_dir,
                               const ProgressSink& progress, const SavedMapSource& map_source = {});

nlohmann::json RunSlamJob(const nlohmann::json& params, const JobContext& context);

// The job type (its validation, references and run), for JobTypes::Add.
JobType SlamJobType();

}  // namespace omnirig::api
