#pragma once
// The "sample" job type: renders one of `omnirig synth`'s presets, small, into the job's dataset,
// so that a new user has data for each step of the first hour with one click (the page's
// first-run panel), without shipping image files.
//
//   POST /api/v1/jobs {"type": "sample", "dataset": ID,
//                      "params": {"preset": "mono-calib" | "stereo-board" | "stereo-sequence"}}
//
// mono-calib: 8 board views of one camera (a calibration job's input); stereo-board: 8 board
// pairs in cam0/ and cam1/ (a relative_pose job's input); stereo-sequence: 12 frames of the rig
// moving through a room in cam0/ and cam1/, with trajectory.tum (a slam job's input and ground
// truth). Images are 640x480. The preset's ground_truth.json is the job's artifact.
// Result: {"preset", "num_files", "image_size": [640, 480], "ground_truth":
// "sample/ground_truth.json"}

#include <cstddef>
#include <filesystem>
#include <functional>
#include <string>

#include "api/job_types.h"

namespace omnirig::api {

// Moves the rendered images (*.png) and trajectory.tum under `dir` into dataset `dataset_id`,
// named by their paths relative to `dir`, and returns how many it added (the service's: it
// records them as an upload would). Throws InvalidArgument when the dataset is gone.
using AddFilesToDataset =
    std::function<size_t(const std::string& dataset_id, const std::filesystem::path& dir)>;

// The job type; its run renders into the job's output folder, then hands the files to
// `add_files`.
JobType SampleJobType(AddFilesToDataset add_files);

}  // namespace omnirig::api
