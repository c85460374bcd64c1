#pragma once
// Accuracy of a SLAM run on a synthetic sequence (engine/synth): trajectory against the
// rendered poses, map points against the scene's surfaces, and the calibration the run ended
// with against the one the renderer used. Test and benchmark support: links engine/synth.

#include "engine/slam/evaluation.h"
#include "engine/slam/slam.h"
#include "engine/synth/presets.h"

namespace omnirig::slam {

struct SequenceAccuracy {
  int num_tracked = 0;
  TrajectoryErrors trajectory;  // over the tracked frames (zeros with fewer than two)
  int num_map_points = 0;
  // Each point's distance relative to its range from the nearest true rig position; median.
  double map_median_percent_of_range = 0.0;
  // CalibrationPixelRms over each camera's mirror annulus, and the rotation error of
  // cam0_from_cam1, of the calibration the run ended with (refined or as given).
  double calibration_rms_px[2] = {0.0, 0.0};
  double rig_rotation_error_deg = 0.0;
};

// `rig` is the calibration the run ended with. Map points are brought into the ground truth's
// world by the first poses' alignment (the first tracked frame anchors the estimate).
SequenceAccuracy EvaluateOnSequence(const synth::StereoSequence& sequence,
                                    const SlamResult& result, const StereoRig& rig);

// The calibration error the refinement tests and bench_slam hand SLAM: both focal lengths
// +0.5 %, principal points moved by (1.5, -1) px in cam0 and (-1, 1.5) px in cam1, cam1 turned
// by 0.2 degrees. The baseline is kept: it is the metric scale, which no residual observes.
StereoRig PerturbedCalibration(const StereoRig& rig, double rig_rotation_deg = 0.2);

// A short sequence the SLAM tests render: 640x480, 15 cm steps, image noise 1 grey level.
synth::StereoSequenceOptions ShortSequenceOptions(int num_frames);

}  // namespace omnirig::slam
