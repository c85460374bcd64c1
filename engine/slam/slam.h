#pragma once
// Stereo omnidirectional SLAM (the paper's section 4, plus the global bundle adjustment it
// leaves as future work). Per frame: mirror mask, SIFT in both cameras, cam0-cam1 matches on
// the rig's epipolar curves, triangulation. Between the last tracked frame and the new one:
// descriptor matches, the essential matrix on the sphere with RANSAC, the metric scale from
// the stereo points (eq. 18, robust), then the pose refined against the map's landmarks in both
// cameras. A local bundle adjustment of the last frames follows every frame, a global one ends
// the run. Frames that cannot be tracked are reported with the reason; the next good frame
// re-initialises from its stereo points and the run goes on. A frame that then fails against
// the re-initialised one tries the last keyframe tied to the first frame's world
// (relocalisation), which brings the trajectory back into that world.
//
// Frames: the rig frame is cam0's frame; the world frame is the rig frame of the first
// tracked frame.

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "engine/geometry/camera_model.h"
#include "engine/slam/bundle_adjustment.h"
#include "engine/slam/features.h"
#include "engine/slam/map_io.h"
#include "engine/slam/matching.h"
#include "engine/slam/motion.h"
#include "engine/stereo/essential.h"
#include "engine/util/progress.h"

namespace omnirig::slam {

struct SlamOptions {
  FeatureOptions features;
  StereoMatchOptions stereo;
  double temporal_max_descriptor_ratio = 0.8;
  // Temporal candidates must lie within this angle of the feature's bearing turned by the last
  // step's rotation (constant-velocity prior); the exhaustive search is the fallback.
  double temporal_gate_rad = 0.35;
  EssentialRansacOptions essential = DefaultEssentialOptions();
  ScaleOptions scale;
  BundleAdjustmentOptions bundle_adjustment;
  // The local bundle adjustment after each frame frees the last few poses (0 = none). On the
  // synthetic room the global adjustment alone reaches the same accuracy; the local one keeps
  // the landmarks that tracking relies on accurate on long sequences.
  int local_window_frames = 3;
  int local_max_iterations = 5;
  bool global_bundle_adjustment = true;
  // What the global adjustment refines of the calibration (the local windows keep it fixed:
  // a few frames do not constrain it). Needs global_bundle_adjustment.
  CalibrationRefinementOptions calibration_refinement;
  // A frame is untrackable below these.
  double min_mean_intensity = 12.0;  // grey level inside the mirror (a black image)
  int min_features = 80;             // per camera (blur, a covered lens)
  int min_stereo_points = 25;
  int min_matches = 25;              // with the last tracked frame
  int min_tracked_landmarks = 15;    // map points confirmed in the new frame
  // Map points exported need observations from this many rig positions: a point seen from one
  // position only rests on the 100 mm stereo baseline, one seen from several on the motion's.
  int min_map_point_frames = 2;
  int num_threads = 1;

  static EssentialRansacOptions DefaultEssentialOptions();
  void Check() const;
};

struct StereoImages {
  cv::Mat cam0;
  cv::Mat cam1;
};
// Loads frame `index`'s images (8-bit BGR or grey). Called once per frame, in order, never
// twice at once, but (with num_threads >= 2) from a worker thread, one frame ahead of tracking.
using StereoFrameLoader = std::function<StereoImages(int index)>;

// Seconds spent per stage.
struct StageTimes {
  double load_s = 0, detect_s = 0, stereo_s = 0, match_s = 0, motion_s = 0, map_s = 0,
         local_ba_s = 0;
  double Total() const {
    return load_s + detect_s + stereo_s + match_s + motion_s + map_s + local_ba_s;
  }
  void Add(const StageTimes& other);
};

struct FrameReport {
  std::string name;
  // "initialised" (first frame), "tracked", "relocalised" (tracked against the last linked
  // keyframe after failing against the last frame, which had been re-initialised),
  // "reinitialised" (a new start from stereo after a tracking failure), "lost" (no pose).
  std::string state;
  // Whether the pose is tied to the first frame's world through tracked frames. False from a
  // re-initialisation until a relocalisation: such poses only continue a motion prediction.
  bool linked = false;
  std::string reason;         // why lost, reinitialised or relocalised
  std::string motion_source;  // "essential+scale", "3d-3d" or "" (no motion estimated)
  int num_features[2] = {0, 0};
  int num_stereo_points = 0;
  int num_matches = 0;            // descriptor matches with the last tracked frame
  int num_essential_inliers = 0;
  int num_scale_inliers = 0;
  int num_tracked_landmarks = 0;  // landmarks confirmed in this frame after pose refinement
  int num_new_landmarks = 0;
  StageTimes times;      // wall clock
  StageTimes cpu_times;  // CPU time of the thread that ran each stage
  std::optional<BundleAdjustmentReport> local_bundle_adjustment;
  std::optional<Rigid3d> world_from_rig;  // final (after the global adjustment)
};

struct SlamResult {
  std::vector<FrameReport> frames;
  std::vector<MapPoint> map;
  std::optional<BundleAdjustmentReport> global_bundle_adjustment;
  // With options.calibration_refinement.refine != kNone: what was refined, or why not (too
  // small a problem, no global adjustment), and the calibration before and after. Poses and
  // map are in the refined calibration's terms.
  std::optional<CalibrationRefinementReport> calibration_refinement;
  StageTimes stage_totals;      // wall clock
  StageTimes cpu_stage_totals;  // CPU time of the threads that ran each stage
  double global_ba_s = 0.0;
  double global_ba_cpu_s = 0.0;  // process CPU time
  double total_s = 0.0;
  double total_cpu_s = 0.0;      // process CPU time, all threads
  int num_tracked = 0;  // frames with a pose
  int num_lost = 0;
};

// Runs SLAM over `frame_names.size()` frames. Throws InvalidArgument on invalid options or an
// image whose size differs from the rig's calibration; Cancelled through `progress`.
SlamResult RunSlam(const StereoRig& rig, const std::vector<std::string>& frame_names,
                   const StereoFrameLoader& load, const SlamOptions& options,
                   const ProgressSink& progress = ProgressSink());

}  // namespace omnirig::slam
