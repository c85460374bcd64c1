#include "engine/slam/slam.h"

#include <cmath>
#include <ctime>
#include <future>
#include <string>

#include "engine/slam/tracker.h"
#include "engine/util/check.h"

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
  OMNIRIG_CHECK(temporal_max_descriptor_ratio > 0 && temporal_max_descriptor_ratio <= 1,
                "temporal_max_descriptor_ratio must be in (0, 1]");
  OMNIRIG_CHECK(local_window_frames >= 0, "local_window_frames must not be negative");
  OMNIRIG_CHECK(keyframe_min_mapped_landmarks >= 1,
                "keyframe_min_mapped_landmarks must be at least 1");
  OMNIRIG_CHECK(local_map_keyframes >= 0, "local_map_keyframes must not be negative");
  OMNIRIG_CHECK(map_gate_rad > 0 && map_gate_rad <= M_PI, "map_gate_rad must be in (0, pi]");
  OMNIRIG_CHECK(local_max_iterations >= 1, "local_max_iterations must be at least 1");
  OMNIRIG_CHECK(temporal_gate_rad > 0 && temporal_gate_rad <= M_PI,
                "temporal_gate_rad must be in (0, pi]");
  OMNIRIG_CHECK(min_features >= 8 && min_stereo_points >= 3 && min_matches >= 8 &&
                    min_tracked_landmarks >= 3,
                "minimum counts are too small to estimate a pose");
  OMNIRIG_CHECK(num_threads >= 1, "num_threads must be at least 1");
  OMNIRIG_CHECK(min_map_point_frames >= 1, "min_map_point_frames must be at least 1");
  OMNIRIG_CHECK(keyframe_min_tracked_fraction >= 0 && keyframe_min_tracked_fraction <= 1,
                "keyframe_min_tracked_fraction must be in [0, 1]");
  OMNIRIG_CHECK(keyframe_max_distance_m > 0 && keyframe_max_rotation_deg > 0,
                "keyframe_max_distance_m and keyframe_max_rotation_deg must be positive");
  OMNIRIG_CHECK(loop_min_keyframe_gap >= 1 && loop_max_candidates >= 1,
                "loop_min_keyframe_gap and loop_max_candidates must be at least 1");
  OMNIRIG_CHECK(loop_min_score >= 0 && loop_min_score <= 1, "loop_min_score must be in [0, 1]");
  OMNIRIG_CHECK(loop_max_distance_m > 0, "loop_max_distance_m must be positive");
  OMNIRIG_CHECK(loop_max_drift_fraction >= 0, "loop_max_drift_fraction must not be negative");
  OMNIRIG_CHECK(loop_min_inliers >= 8, "loop_min_inliers must be at least 8");
  OMNIRIG_CHECK(loop_min_correction_m >= 0 && loop_min_correction_deg >= 0,
                "loop corrections must not be negative");
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
