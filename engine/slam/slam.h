#pragma once
// Stereo omnidirectional SLAM (the paper's section 4, plus the global bundle adjustment it
// leaves as future work, keyframes, loop closure and relocalisation for long runs). Per frame:
// mirror mask, SIFT in both cameras, cam0-cam1 matches on the rig's epipolar curves,
// triangulation. Between the last tracked frame and the new one: descriptor matches, the
// essential matrix on the sphere with RANSAC, the metric scale from the stereo points (eq. 18,
// robust), then the pose refined against the map's landmarks tracked into the last frame.
//
// Keyframes: a frame enters the map only when it adds enough new view: too few landmarks
// tracked, against what its reference keyframe (the one sharing the most landmarks with it)
// holds, or it moved or turned far enough from that keyframe. A frame that tracks landmarks of
// keyframes of an earlier passage (after a loop to a mapped place) is matched against them too
// (its local map: their landmarks projected at its pose), so that tracking continues on the old
// keyframes' landmarks and a revisit adds a keyframe only where the map does not cover the view
// (ORB-SLAM's local-map tracking and keyframe decision). A keyframe adds its observations and
// new landmarks, and a local bundle adjustment frees it and the keyframes sharing the most
// landmarks with it. Other frames keep their pose relative to their reference keyframe and
// nothing else, so memory and the per-frame work follow the map, not the frames. The global
// adjustment at the end runs over the keyframes; the other frames follow their keyframes.
//
// Place recognition: every keyframe's bag of words (vocabulary.h) is queried against the older
// keyframes that tracking's estimate puts near enough (loop_max_distance_m plus a drift
// allowance); a candidate is verified on the sphere (descriptors matched within vocabulary
// nodes, essential matrix on bearings, the stereo scale's 3D-3D agreement, then the candidate's
// landmarks in the keyframe). A verified loop
// fuses the landmarks seen again; when the correction it implies is larger than the noise, a
// pose graph (pose_graph.h) spreads it over the keyframes and the global bundle adjustment
// follows. A candidate that fails verification changes nothing.
//
// Frames that cannot be tracked are reported with the reason. A frame that fails against the
// last frame is localised against the whole map (the place recognition's candidates, P3P with
// RANSAC, absolute_pose.h): "relocalised". If that fails too, it starts a new segment from its
// stereo points ("reinitialised", not linked to the first frame's world); the segment's
// keyframes look for mapped places, and the first verified one brings the whole segment's poses
// and landmarks into the map's world ("relinked").
//
// Frames: the rig frame is cam0's frame; the world frame is the rig frame of the first
// tracked frame.

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "engine/estimators/absolute_pose.h"
#include "engine/estimators/essential.h"
#include "engine/estimators/motion.h"
#include "engine/features/features.h"
#include "engine/features/matching.h"
#include "engine/geometry/camera_model.h"
#include "engine/slam/bundle_adjustment.h"
#include "engine/slam/map_io.h"
#include "engine/slam/saved_map.h"
#include "engine/util/progress.h"

namespace omnirig::slam {

// The cam0-cam1 matches of a frame (MatchStereo): on the epipolar curve as seen in cam1,
// triangulated at the rays' midpoint.
struct StereoMatchOptions {
  // Largest angle between a cam1 bearing and the epipolar plane of its cam0 partner; the
  // triangulated point must lie within twice this angle of both bearings.
  double max_epipolar_error_rad = 3e-3;
  double max_descriptor_ratio = 0.8;  // Lowe's, among the candidates on the curve
  // Largest L2 distance between matched descriptors (OpenCV's SIFT scale, descriptors of norm
  // ~512): a lone candidate on the curve passes any ratio test, not this. Also bounds the
  // temporal and loop matches.
  double max_descriptor_distance = 250.0;
  double min_parallax_rad = 0.004;  // ~0.25 degrees: 100 mm baseline seen from ~25 m
  double max_range_m = 30.0;
  EpipolarMatchOptions Matching() const;
  // Range std for ~0.5 px of keypoint noise on cam0's focal length.
  StereoTriangulationOptions Triangulation(const StereoRig& rig) const;
  void Check() const;
};

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
  // A tracked frame becomes a keyframe when it tracks fewer landmarks than this fraction of
  // those its reference keyframe (the one sharing the most landmarks with it) holds, or when it
  // is this far from that keyframe. On the synthetic room (15 cm steps) 0.7 makes every other
  // frame a keyframe, drift 0.058 %; 0.5 every third, drift 0.145 % (every frame, as before
  // keyframes: 0.127 %).
  double keyframe_min_tracked_fraction = 0.7;
  double keyframe_max_distance_m = 1.0;
  double keyframe_max_rotation_deg = 20.0;
  // On a place an earlier passage mapped (a keyframe older than loop_min_keyframe_gap keyframes,
  // within keyframe_max_distance_m and keyframe_max_rotation_deg), a frame that tracks at least
  // this many of that keyframe's landmarks needs no keyframe: the map covers the view (as many
  // as a loop needs confirmed).
  int keyframe_min_mapped_landmarks = 40;
  // The local map a tracked frame is matched against on a revisit: the landmarks of this many
  // keyframes of an earlier passage (older than loop_min_keyframe_gap keyframes), those sharing
  // the most landmarks with it, matched where its pose projects them (within map_gate_rad of
  // the feature's bearing, then the descriptor ratio test).
  int local_map_keyframes = 3;
  double map_gate_rad = 0.02;
  // The local bundle adjustment after each keyframe frees it and the keyframes sharing the most
  // landmarks with it, this many in all (0 = none). On the synthetic room the global adjustment
  // alone reaches the same accuracy; the local one keeps the landmarks that tracking relies on
  // accurate on long sequences.
  int local_window_frames = 3;
  int local_max_iterations = 5;
  // Place recognition and loop closure (needs the global bundle adjustment's map; off: no loops
  // and no re-linking, relocalisation still uses the place recognition).
  bool loop_closure = true;
  int loop_min_keyframe_gap = 10;   // loop candidates are older than this many keyframes
  double loop_min_score = 0.04;     // L1 score of a candidate (0..1; vocabulary.h)
  int loop_max_candidates = 4;      // verified per keyframe, best score first
  int loop_min_inliers = 40;        // essential inliers and landmarks confirmed
  // A loop is a return to a mapped place: the verified keyframe must be this close. Places
  // recognised from further away give weaker relative poses (on the 100 m city block, a match
  // 7.8 m away moved a pose by 28 cm where the drift was millimetres) and are not revisits.
  double loop_max_distance_m = 1.5;
  // Candidates are verified only when tracking's estimate puts them within loop_max_distance_m
  // plus this fraction of the path travelled since them (the drift tracking may have gathered;
  // it measures 0.1-0.5 % on the renders, so 5 % is a wide margin): verification matches every
  // descriptor of both keyframes and is the costly part of place recognition.
  double loop_max_drift_fraction = 0.05;
  // A loop whose correction is below both only fuses the landmarks seen again (the local
  // adjustment absorbs it); above either, the pose graph and the global adjustment run.
  double loop_min_correction_m = 0.05;
  double loop_min_correction_deg = 0.5;
  AbsolutePoseOptions absolute_pose;  // relocalisation
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
  // A map saved by an earlier run (saved_map.h) to localise in: its keyframes are loaded before
  // the first frame, so that every frame is placed in its world (relocalisation against its
  // keyframes, then tracking on its landmarks), and what this run maps where it has nothing
  // joins it. Its keyframes and their poses stay as saved (the adjustments hold them constant:
  // the saved map's world is the world of this run); its landmarks seen again are refined.
  // Null: a new map, whose world is the first frame's.
  std::shared_ptr<const SavedMap> saved_map;

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
// A frame's two images read side by side, cam1's on a thread of its own: decoding is a fifth of
// a frame's work (two PNGs of 1024x768: ~38 ms of 210), and the front end would otherwise wait
// for it on one core (the 600-frame loop: 7.6 -> 8.4 frames/s on 2 idle cores). `read(c)`
// returns camera c's image and must be safe to call for 0 and 1 at once; an exception of either
// is rethrown after both have returned.
StereoImages ReadBoth(const std::function<cv::Mat(int camera)>& read);

// Seconds spent per stage.
struct StageTimes {
  double load_s = 0, detect_s = 0, stereo_s = 0, match_s = 0, motion_s = 0, map_s = 0,
         local_ba_s = 0;
  // Place recognition, loop verification and closure, relocalisation, re-linking.
  double loop_s = 0;
  double Total() const {
    return load_s + detect_s + stereo_s + match_s + motion_s + map_s + local_ba_s + loop_s;
  }
  void Add(const StageTimes& other);
};

struct FrameReport {
  std::string name;
  // "initialised" (first frame), "tracked", "relocalised" (localised against the map's
  // keyframes after failing against the last frame), "reinitialised" (a new start from stereo
  // after a tracking failure), "relinked" (a keyframe of a re-initialised segment that
  // recognised a mapped place: the segment was moved into the map's world), "lost" (no pose).
  std::string state;
  // Whether the pose is tied to the first frame's world. False from a re-initialisation until a
  // relocalisation or a re-linking (which makes the whole segment linked): such poses only
  // continue a motion prediction.
  bool linked = false;
  bool keyframe = false;  // entered the map
  // With a saved map: the frame is localised in it, i.e. linked to its world and confirming at
  // least min_tracked_landmarks of its landmarks (false without a saved map).
  bool in_map = false;
  // The frame's reference keyframe (frame index, -1: none): on a revisit tracked on the map, the
  // earlier passage's keyframe near it; elsewhere the keyframe sharing the most landmarks with
  // it. A non-keyframe's pose follows it.
  int reference_keyframe = -1;
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

// A verified loop: keyframe `frame_index` recognised keyframe `matched_frame_index` (-1 for a
// keyframe of the saved map, whose name `matched_frame` then is).
struct LoopReport {
  std::string frame;
  int frame_index = -1;
  std::string matched_frame;
  int matched_frame_index = -1;
  int inliers = 0;  // landmarks of the matched keyframe confirmed in the frame
  // How far the loop moved the frame's pose: position (m) and rotation (deg) between the pose
  // tracking had given it and the one the matched keyframe gives it.
  double correction_m = 0.0;
  double correction_deg = 0.0;
  bool pose_graph = false;  // the correction ran the pose graph and global adjustment
};

struct SlamResult {
  std::vector<FrameReport> frames;
  std::vector<LoopReport> loops;
  int num_keyframes = 0;
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
  // The map to save for later runs: its keyframes in the world of the first frame or, with a
  // saved map, in that map's world, the saved map's keyframes first.
  SavedMap saved_map;
  int num_frames_in_map = 0;  // frames with in_map (with a saved map)
};

// Runs SLAM over `frame_names.size()` frames. Throws InvalidArgument on invalid options or an
// image whose size differs from the rig's calibration; Cancelled through `progress`.
SlamResult RunSlam(const StereoRig& rig, const std::vector<std::string>& frame_names,
                   const StereoFrameLoader& load, const SlamOptions& options,
                   const ProgressSink& progress = ProgressSink());

}  // namespace omnirig::slam
