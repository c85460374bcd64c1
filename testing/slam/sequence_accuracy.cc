#include "testing/slam/sequence_accuracy.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "testing/slam/surface_distance.h"

namespace omnirig::slam {
namespace {

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

}  // namespace

SequenceAccuracy EvaluateOnSequence(const synth::StereoSequence& sequence,
                                    const SlamResult& result, const StereoRig& rig) {
  SequenceAccuracy accuracy;
  accuracy.num_tracked = result.num_tracked;
  const UnifiedIntrinsics* estimate[2] = {&rig.cam0.intrinsics, &rig.cam1.intrinsics};
  for (int c = 0; c < 2; ++c) {
    const synth::SynthCamera& camera = sequence.cameras[c];
    accuracy.calibration_rms_px[c] = CalibrationPixelRms(
        camera.model.intrinsics, *estimate[c], camera.hole_radius_px, camera.rim_radius_px);
  }
  accuracy.rig_rotation_error_deg =
      RotationDistanceRad(rig.cam0_from_cam1.rotation, sequence.rig.cam0_from_cam1.rotation) *
      180.0 / M_PI;
  std::vector<Rigid3d> estimate_poses, truth;
  for (size_t i = 0; i < result.frames.size(); ++i) {
    if (!result.frames[i].world_from_rig) continue;
    estimate_poses.push_back(*result.frames[i].world_from_rig);
    truth.push_back(sequence.world_from_rig[i]);
  }
  if (estimate_poses.size() < 2) return accuracy;
  accuracy.trajectory = EvaluateTrajectory(estimate_poses, truth);
  const Rigid3d gt_from_estimate = truth.front() * estimate_poses.front().Inverse();
  std::vector<double> relative;
  for (const MapPoint& point : result.map) {
    const Eigen::Vector3d p = gt_from_estimate * point.point_in_world;
    double range = 1e9;
    for (const Rigid3d& pose : truth) range = std::min(range, (p - pose.translation).norm());
    const double d = DistanceToSceneSurface(sequence.scene, p);
    relative.push_back(100.0 * d / range);
  }
  accuracy.num_map_points = static_cast<int>(result.map.size());
  accuracy.map_median_percent_of_range = Median(relative);
  return accuracy;
}

StereoRig PerturbedCalibration(const StereoRig& rig, double rig_rotation_deg) {
  StereoRig perturbed = rig;
  for (CameraModel* camera : {&perturbed.cam0, &perturbed.cam1}) {
    camera->intrinsics.gamma_u() *= 1.005;
    camera->intrinsics.gamma_v() *= 1.005;
  }
  perturbed.cam0.intrinsics.u0() += 1.5;
  perturbed.cam0.intrinsics.v0() -= 1.0;
  perturbed.cam1.intrinsics.u0() -= 1.0;
  perturbed.cam1.intrinsics.v0() += 1.5;
  perturbed.cam0_from_cam1.rotation =
      Eigen::Quaterniond(
          Eigen::AngleAxisd(rig_rotation_deg * M_PI / 180.0, Eigen::Vector3d(1, -2, 0.5).normalized())) *
      rig.cam0_from_cam1.rotation;
  return perturbed;
}

synth::StereoSequenceOptions ShortSequenceOptions(int num_frames) {
  synth::StereoSequenceOptions options;
  options.num_frames = num_frames;
  options.path_length_m = 0.15 * num_frames;
  options.width = 640;
  options.height = 480;
  options.render.noise_sigma = 1.0;
  return options;
}

}  // namespace omnirig::slam
