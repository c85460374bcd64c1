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

#include "server/service.h"

namespace omnirig::server {

// Registers (or re-registers) the job type for `state`'s store and data folder. Job types are
// process-wide: the latest Service constructed owns "sample" jobs (one Service per process, as
// `omnirig serve` runs it; tests that hold two at once must not run sample jobs on the first).
void RegisterSampleJobType(ServiceState& state);

}  // namespace omnirig::server
