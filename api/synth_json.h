#pragma once
// Ground truth of the synthetic presets (engine/synth/presets.h) as JSON, and writers that save a
// preset to a folder: PNG images plus ground_truth.json (plus trajectory.tum for sequences).
//
// ground_truth.json, common keys:
//   "format": "omnirig-synth", "version": 1, "preset": "mono-calib" | "stereo-board" |
//   "stereo-sequence" | "stereo-loop", "image_size": [w, h],
//   "scene": {"world_frame": ..., "background_rgb": [r, g, b],
//             "primitives": [{"kind", "name", "world_from_local": pose, "size_m": [x, y, z],
//                             "texture": {"style", "seed", "color_rgb", "texel_size_m",
//                                         "shapes_per_m2"} | "board": board}]}
//   camera: the api/camera_json.h camera ({"model", "image_size", "intrinsics": {"xi",
//           "gamma_u", "gamma_v", "u0", "v0", "alpha", "k1".."k5"}}) plus "rim_radius_px" and
//           "hole_radius_px"
//   pose:   {"rotation_wxyz": [w, x, y, z], "translation_m": [x, y, z]}
//   board:  {"cols", "rows" (inner corners), "square_size_m", "margin_m",
//            "corners_in_board_m": [[x, y, 0], ...] row-major}
//   corners_px: [[u, v] | null, ...] in board-corner order, exact projections (pixel centre
//               convention (0, 0) = centre of the top-left pixel), null where a corner does not
//               project inside the mirror annulus
// mono-calib:      "camera", "board", "images": [{"name", "file", "cam_from_board",
//                  "corners_px"}]; the scene's world frame is the camera frame. In both board
//                  presets the scene lists the background only: the board moves per image.
// stereo-board:    "rig": api::RigToJson (cam0_from_cam1, baseline_m, cameras.cam0/cam1, each
//                  camera with its mirror radii), "board", "pairs": [{"name", "files": {"cam0",
//                  "cam1"}, "cam0_from_board", "cam1_from_board", "corners_px": {"cam0",
//                  "cam1"}}]; the scene's world frame is cam0's frame.
// stereo-sequence: "rig", "rig_frame": "cam0", "environment": "room" | "street",
//                  "frames": [{"name", "timestamp_s", "files": {"cam0", "cam1"},
//                  "world_from_rig"}], "trajectory_file": "trajectory.tum"; z-up world.
// stereo-loop:     as stereo-sequence with "environment": "city-block", plus "loop":
//                  {"length_m" (one lap), "num_laps", "lighting_change",
//                  "motion_blur_exposure_s", "motion_blur_samples"} and per frame "lap".
// Image files: mono DIR/NAME.png; stereo DIR/cam0/NAME.png and DIR/cam1/NAME.png.
// trajectory.tum: one line per frame, "timestamp tx ty tz qx qy qz qw" of world_from_rig
// (slam::WriteTum).

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "engine/synth/presets.h"

namespace omnirig::api {

nlohmann::json CornersToJson(const std::vector<Eigen::Vector2d>& corners_px);
nlohmann::json MonoCalibrationSetToJson(const synth::MonoCalibrationSet& set);
nlohmann::json StereoBoardSetToJson(const synth::StereoBoardSet& set);
nlohmann::json StereoSequenceToJson(const synth::StereoSequence& sequence,
                                    const std::string& environment);

// Write the images and ground_truth.json (and trajectory.tum) into `dir`, creating it. Throw
// std::runtime_error when a file cannot be written.
void WriteMonoCalibrationSet(const synth::MonoCalibrationSet& set, const std::string& dir);
void WriteStereoBoardSet(const synth::StereoBoardSet& set, const std::string& dir);
// The parts of WriteStereoSequence, for sequences rendered frame by frame
// (synth::RenderStereoSequence): one frame's two images, then ground_truth.json and
// trajectory.tum.
void WriteStereoFrame(const std::string& name, const cv::Mat& cam0_image,
                      const cv::Mat& cam1_image, const std::string& dir);
void WriteStereoSequenceGroundTruth(const synth::StereoSequence& sequence,
                                    const std::string& environment, const std::string& dir);
void WriteStereoSequence(const synth::StereoSequence& sequence, const std::string& environment,
                         const std::string& dir);

// The sequence as videos instead of PNG folders, with the same ground_truth.json and
// trajectory.tum: DIR/cam0.EXT and DIR/cam1.EXT, or with `stacked` one DIR/stacked.EXT (cam0 on
// top of cam1). `format`: "mp4" (MPEG-4 part 2, 'mp4v', lossy), "avi" (Motion JPEG, lossy) or
// "mkv" (FFV1, lossless): codecs Debian's OpenCV writes through FFmpeg. The frame rate is
// 1 / the sequence's frame interval, so the containers' timestamps are the ground truth's.
// Throws InvalidArgument for another format, std::runtime_error when the writer cannot open.
void WriteStereoSequenceVideos(const synth::StereoSequence& sequence,
                               const std::string& environment, const std::string& dir,
                               const std::string& format, bool stacked);

}  // namespace omnirig::api
