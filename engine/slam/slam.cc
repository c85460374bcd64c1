#include "engine/slam/slam.h"

#include <cmath>
#include <ctime>
#include <future>
#include <string>

#include "engine/slam/tracker.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig::slam {

using internal::StageClock;
using internal::Tracker;

EssentialRansacOptions SlamOptions::DefaultEssentialOptions() {
  EssentialRansacOptions options;
  options.max_angular_error_rad = 2e-3;  // ~0.5 px for SIFT keypoints on a ~240 px gamma
  options.max_iterations = 2000;
  options.min_inliers = 20;
  return options;
}

EpipolarMatchOptions StereoMatchOptions::Matching() const {
  EpipolarMatchOptions matching;
  matching.max_epipolar_error_rad = max_epipolar_error_rad;
  matching.check_both_cameras = false;
  matching.max_descriptor_ratio = max_descriptor_ratio;
  matching.max_descriptor_distance = max_descriptor_distance;
  matching.mutual_check = true;
  return matching;
}

StereoTriangulationOptions StereoMatchOptions::Triangulation(const StereoRig& rig) const {
  StereoTriangulationOptions triangulation;
  triangulation.optimal_angular = false;
  triangulation.triangulation.min_parallax_rad = min_parallax_rad;
  triangulation.triangulation.max_angular_error_rad = 2 * max_epipolar_error_rad;
  triangulation.triangulation.bearing_std_rad = 0.5 / rig.cam0.intrinsics.gamma_u();
  triangulation.max_range_m = max_range_m;
  return triangulation;
}

void StereoMatchOptions::Check() const {
  OMNIRIG_CHECK_POSITIVE(max_epipolar_error_rad);
  OMNIRIG_CHECK_IN(max_descriptor_ratio, '(', 0, 1, ']');
  OMNIRIG_CHECK_POSITIVE(max_descriptor_distance);
  OMNIRIG_CHECK_NON_NEGATIVE(min_parallax_rad);
  OMNIRIG_CHECK_POSITIVE(max_range_m);
}

void SlamOptions::Check() const {
  features.Check();
  stereo.Check();
  essential.Check();
  scale.Check();
  bundle_adjustment.Check();
  calibration_refinement.Check();
  OMNIRIG_CHECK(calibration_refinement.refine == CalibrationRefinement::kNone ||
                    global_bundle_adjustment,
                "refining the calibration needs the global bundle adjustment");
  OMNIRIG_CHECK_IN(temporal_max_descriptor_ratio, '(', 0, 1, ']');
  OMNIRIG_CHECK_NON_NEGATIVE(local_window_frames);
  OMNIRIG_CHECK_AT_LEAST(keyframe_min_mapped_landmarks, 1);
  OMNIRIG_CHECK_NON_NEGATIVE(local_map_keyframes);
  OMNIRIG_CHECK_IN(map_gate_rad, '(', 0, M_PI, ']');
  OMNIRIG_CHECK_AT_LEAST(local_max_iterations, 1);
  OMNIRIG_CHECK_IN(temporal_gate_rad, '(', 0, M_PI, ']');
  OMNIRIG_CHECK(min_features >= 8 && min_stereo_points >= 3 && min_matches >= 8 &&
                    min_tracked_landmarks >= 3,
                "minimum counts are too small to estimate a pose");
  OMNIRIG_CHECK_AT_LEAST(num_threads, 1);
  OMNIRIG_CHECK_AT_LEAST(min_map_point_frames, 1);
  OMNIRIG_CHECK_IN(keyframe_min_tracked_fraction, '[', 0, 1, ']');
  OMNIRIG_CHECK_POSITIVE(keyframe_max_distance_m);
  OMNIRIG_CHECK_POSITIVE(keyframe_max_rotation_deg);
  OMNIRIG_CHECK_AT_LEAST(loop_min_keyframe_gap, 1);
  OMNIRIG_CHECK_AT_LEAST(loop_max_candidates, 1);
  OMNIRIG_CHECK_IN(loop_min_score, '[', 0, 1, ']');
  OMNIRIG_CHECK_POSITIVE(loop_max_distance_m);
  OMNIRIG_CHECK_NON_NEGATIVE(loop_max_drift_fraction);
  OMNIRIG_CHECK_AT_LEAST(loop_min_inliers, 8);
  OMNIRIG_CHECK_NON_NEGATIVE(loop_min_correction_m);
  OMNIRIG_CHECK_NON_NEGATIVE(loop_min_correction_deg);
  absolute_pose.Check();
}

void StageTimes::Add(const StageTimes& o) {
  load_s += o.load_s;
  detect_s += o.detect_s;
  stereo_s += o.stereo_s;
  match_s += o.match_s;
  motion_s += o.motion_s;
  map_s += o.map_s;
  local_ba_s += o.local_ba_s;
  loop_s += o.loop_s;
}

StereoImages ReadBoth(const std::function<cv::Mat(int camera)>& read) {
  std::future<cv::Mat> cam1 = std::async(std::launch::async, read, 1);
  StereoImages images;
  images.cam0 = read(0);  // on a throw, `cam1`'s destructor waits for the other read
  images.cam1 = cam1.get();
  return images;
}

SlamResult RunSlam(const StereoRig& rig, const std::vector<std::string>& frame_names,
                   const StereoFrameLoader& load, const SlamOptions& options,
                   const ProgressSink& progress) {
  options.Check();
  OMNIRIG_CHECK(!frame_names.empty(), "SLAM needs at least one stereo frame");
  const StageClock total(CLOCK_PROCESS_CPUTIME_ID);
  SlamResult result;
  Tracker tracker(rig, options, progress);
  const int n = static_cast<int>(frame_names.size());
  // With two threads the front end of frame i + 1 (features of both cameras side by side,
  // stereo) runs while the back end of frame i (tracking, local bundle adjustment) does.
  const bool pipelined = options.num_threads >= 2;
  auto front_end = [&](int i) {
    return tracker.FrontEnd(i, frame_names[i], load, /*parallel_cameras=*/pipelined);
  };
  std::future<Tracker::FrontEndResult> next;
  if (pipelined) next = std::async(std::launch::async, front_end, 0);
  for (int i = 0; i < n; ++i) {
    progress.ThrowIfCancelled();
    Tracker::FrontEndResult front = pipelined ? next.get() : front_end(i);
    if (pipelined && i + 1 < n) next = std::async(std::launch::async, front_end, i + 1);
    FrameReport report = tracker.BackEnd(std::move(front), /*last_frame=*/i + 1 == n);
    result.stage_totals.Add(report.times);
    result.cpu_stage_totals.Add(report.cpu_times);
    progress.Report(0.95 * (i + 1) / n, "track",
                    "frame " + std::to_string(i + 1) + "/" + std::to_string(n) + " " +
                        frame_names[i] + ": " + report.state +
                        (report.reason.empty() ? "" : " (" + report.reason + ")"));
    result.frames.push_back(std::move(report));
  }
  tracker.Finish(progress, &result);
  result.total_s = total.WallSeconds();
  result.total_cpu_s = total.CpuSeconds();
  progress.Report(1.0, "done", std::to_string(result.num_tracked) + " of " + std::to_string(n) +
                                   " frames tracked, " + std::to_string(result.map.size()) +
                                   " map points");
  return result;
}

}  // namespace omnirig::slam
