#pragma once
// The SLAM tracker behind RunSlam (slam.h), shared by the files that define its members:
// tracker.cc (front end, tracking, keyframes, local and global adjustment), loop_closure.cc
// (place verification, loops, the pose graph, landmark fusion) and relocalisation.cc
// (relocalisation against the map, new segments and their re-linking). Not a public interface.

#include <ctime>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "engine/slam/pose_graph.h"
#include "engine/slam/slam.h"
#include "engine/slam/vocabulary.h"
#include "engine/util/timer.h"

namespace omnirig::slam::internal {

// Seconds on `clock` (CLOCK_THREAD_CPUTIME_ID, CLOCK_PROCESS_CPUTIME_ID).
double CpuSeconds(clockid_t clock);

// Wall-clock and CPU time of one stage: the calling thread's CPU time (stages run on two
// threads at once), or the whole process's for a stage that owns the machine. On a shared
// machine the CPU time is the stable measure of the work; the wall time is what a user waits.
class StageClock {
 public:
  explicit StageClock(clockid_t clock = CLOCK_THREAD_CPUTIME_ID) : clock_(clock) { Restart(); }
  void Restart() {
    wall_.Restart();
    cpu_start_ = internal::CpuSeconds(clock_);
  }
  void ChargeTo(double StageTimes::*stage, FrameReport* report) const {
    report->times.*stage += WallSeconds();
    report->cpu_times.*stage += CpuSeconds();
  }
  double WallSeconds() const { return wall_.ElapsedSeconds(); }
  double CpuSeconds() const { return internal::CpuSeconds(clock_) - cpu_start_; }

 private:
  clockid_t clock_;
  Timer wall_;
  double cpu_start_ = 0;
};

// A keyframe that shares landmarks with a tracked frame, as the keyframe decision sees it.
struct CovisibleKeyframe {
  int keyframe = -1;        // its frame index
  int shared = 0;           // its landmarks the frame tracks
  int held = 0;             // landmarks it holds (cam0)
  int keyframes_since = 0;  // keyframes made after it
  Rigid3d keyframe_from_frame;
};

struct KeyframeDecision {
  int reference_keyframe = -1;  // -1: none (the frame tracks no keyframe's landmarks)
  // The reference is a keyframe of an earlier passage through the place (more than
  // loop_min_keyframe_gap keyframes old), within keyframe_max_distance_m and
  // keyframe_max_rotation_deg, of whose landmarks the frame tracks at least
  // keyframe_min_mapped_landmarks: the map covers the view.
  bool on_mapped_place = false;
  bool needs_keyframe = true;
};

// The keyframe decision of a tracked frame that tracks `num_tracked_landmarks` landmarks, from
// the keyframes sharing them (most shared first; those after the first sharing fewer than
// keyframe_min_mapped_landmarks may be left out). On a mapped place (KeyframeDecision) no
// keyframe; elsewhere the reference is the most shared keyframe, and a keyframe is needed when
// the frame is beyond keyframe_max_distance_m / keyframe_max_rotation_deg of it or tracks fewer
// than keyframe_min_tracked_fraction of the landmarks it holds.
KeyframeDecision DecideKeyframe(const std::vector<CovisibleKeyframe>& covisible,
                                int num_tracked_landmarks, const SlamOptions& options);

// Everything kept of a tracked frame for matching the next one. The map's copy of a keyframe
// (StoredKeyframe) keeps cam0's features, with the descriptors as bytes, and the stereo points.
struct Frame {
  int index = -1;
  CameraFeatures features[2];
  std::vector<int> stereo_of_feature0;  // index into `stereo`, -1 when none
  std::vector<StereoPoint> stereo;
  std::vector<int> landmark_of[2];      // per feature, -1 when none
  // Per cam0 feature, the cam0 feature of keyframe `chain_keyframe` it was tracked from through
  // the frames since (-1: none): a landmark the next keyframe creates for it gains that
  // keyframe's observation, so that new landmarks are seen from two rig positions at once.
  std::vector<int> keyframe_feature_of;
  int chain_keyframe = -1;
  // Once tracked on the local map: its reference keyframe (a non-keyframe keeps its pose
  // relative to it) and whether it adds enough new view to become a keyframe.
  KeyframeDecision keyframe_decision;
  bool keyframe = false;
  // cam0's bag of words and each cam0 feature's word, once computed (relocalisation needs
  // them before the frame becomes a keyframe, which needs them again).
  std::optional<BowVector> bow;
  std::vector<int> words;
};

struct StoredKeyframe {
  Frame frame;
  BowVector bow;
  std::vector<int> words;  // per cam0 feature, its vocabulary word
  int order = 0;  // position among the keyframes
  double path_m = 0;  // the path travelled from the first keyframe, along the keyframes
  bool linked = false;
};

// A place recognised and verified: the frame seen from keyframe `keyframe`.
struct PlaceMatch {
  int keyframe = -1;
  Rigid3d rig_from_world;  // the frame's pose in the keyframe's world
  std::vector<std::pair<int, int>> landmark_of_feature;  // (frame's cam0 feature, landmark)
  int inliers = 0;  // landmarks confirmed
};

// SIFT descriptors as floats (the map keeps them as bytes: OpenCV's SIFT rounds them).
cv::Mat FloatDescriptors(const cv::Mat& descriptors);

double RotationDeg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);

class Tracker {
 public:
  // `progress` is asked for cancellation only (inside the bundle adjustments); RunSlam
  // reports the frames.
  Tracker(const StereoRig& rig, const SlamOptions& options, const ProgressSink& progress)
      : rig_(rig),
        options_(options),
        cancellation_{nullptr, progress.is_cancelled},
        vocabulary_(DefaultVocabulary()) {
    if (options.saved_map) LoadMap(*options.saved_map);
  }

  // The per-frame half that needs no map: load, mask, features, stereo points. Runs one frame
  // ahead of BackEnd() on a worker thread; never two FrontEnd() calls at once.
  struct FrontEndResult {
    Frame frame;
    FrameReport report;
    bool usable = false;
  };
  FrontEndResult FrontEnd(int index, const std::string& name, const StereoFrameLoader& load,
                          bool parallel_cameras);
  // Tracking, relocalisation or a new segment; for a keyframe the map update, place
  // recognition and local bundle adjustment. `last_frame` makes the frame a keyframe.
  // `on_pose` (may be empty) hears the frame's report, with world_from_rig as tracked, once the
  // pose and the keyframe decision are known, before a keyframe's mapping refines them.
  FrameReport BackEnd(FrontEndResult front, bool last_frame,
                      const std::function<void(const FrameReport&)>& on_pose = {});
  // The end of the run: the global adjustment over the keyframes (into `result`), the other
  // frames placed relative to their keyframes, the loops and per-frame links into `result`.
  void Finish(const ProgressSink& progress, SlamResult* result);
  // The run so far without changing it: each frame's world_from_rig as the map holds it now (a
  // non-keyframe placed by its keyframe, as Finish() will), nullopt for a frame without a pose,
  // and the map points as Finish() would export them. For a live run's artifacts.
  std::vector<std::optional<Rigid3d>> CurrentWorldFromRig() const;
  std::vector<MapPoint> CurrentMap() const;
  int num_keyframes() const { return static_cast<int>(keyframe_order_.size()); }
  SlamMap& map() { return map_; }
  // The map's frame index of the run's first frame: the saved map's keyframes come first.
  int first_frame() const { return first_frame_; }

 private:
  // Checks the image sizes (throws), finds the mirror masks on the first usable images, and
  // returns false (with report->reason) for a black image.
  bool CheckImages(const StereoImages& images, FrameReport* report);
  // Returns false (with report->reason) when the frame has too little to work with.
  bool DetectAndMatchStereo(const StereoImages& images, bool parallel_cameras, Frame* frame,
                            FrameReport* report);
  // Matches `frame` with `reference` (the last tracked frame), estimates the motion between
  // them and refines the pose against the landmarks tracked into the reference. `matches` are
  // (reference feature, frame feature) in cam0; false with report->reason on failure.
  bool TrackAgainst(const Frame& reference, Frame* frame,
                    std::vector<std::pair<int, int>>* matches, FrameReport* report);
  // Estimates curr_from_prev with E + scale (or 3D-3D); false with the reason on failure.
  bool EstimateMotion(const Frame& reference, const Frame& frame,
                      const std::vector<std::pair<int, int>>& matches, Rigid3d* curr_from_prev,
                      FrameReport* report);
  // Refines the frame's pose (map_.rig_from_world, initialised by the caller) against the
  // landmarks of the reference's matched features; links the confirmed ones in `frame` (the
  // map gains the observations only if the frame becomes a keyframe).
  bool TrackLandmarks(const Frame& reference, Frame* frame,
                      const std::vector<std::pair<int, int>>& matches, FrameReport* report);
  // TrackLandmarks() with the landmarks given per cam0 feature: (frame's feature, landmark).
  bool RefineAgainstLandmarks(const std::vector<std::pair<int, int>>& landmark_of_feature,
                              Frame* frame, FrameReport* report);
  // Map reuse: the landmarks of the keyframes of an earlier passage that share the most
  // landmarks with the tracked frame (its local map on a revisit), projected at its pose and
  // matched within options_.map_gate_rad, join the ones tracked from the last frame; the pose is
  // refined against all of them. Sets frame->keyframe_decision. After a loop to a mapped place,
  // this carries tracking onto the old keyframes' landmarks, so that the revisit is covered by
  // the map it already has.
  void TrackLocalMap(Frame* frame, FrameReport* report);
  // Sets frame->keyframe_decision from the keyframes sharing landmarks with the frame
  // (CovisibleKeyframes(), most first).
  void DecideKeyframe(const std::vector<std::pair<int, int>>& covisible, Frame* frame,
                      const FrameReport& report) const;
  // Keyframes made after keyframe `keyframe`: more than options_.loop_min_keyframe_gap make it
  // one of an earlier passage through its place.
  // A keyframe of the saved map is always of an earlier passage.
  int KeyframesSince(int keyframe) const {
    if (IsSaved(keyframe)) {
      return static_cast<int>(keyframe_order_.size()) + options_.loop_min_keyframe_gap;
    }
    return static_cast<int>(keyframe_order_.size()) - 1 - keyframes_.at(keyframe).order;
  }
  // Keyframes that observe the landmarks `landmark_of` holds, by the number observed, most first.
  std::vector<std::pair<int, int>> CovisibleKeyframes(const std::vector<int>& landmark_of) const;
  // Matches of keyframe `keyframe`'s landmarks not yet in `frame`, at the frame's pose:
  // (frame's cam0 feature, landmark).
  std::vector<std::pair<int, int>> MatchKeyframeLandmarks(int keyframe, const Frame& frame) const;
  // Localises `frame` against the place recognition's candidate keyframes (P3P + RANSAC, then
  // the candidate's landmarks); on success fills `matches` (with the keyframe) and the report
  // and returns the keyframe's frame.
  const Frame* Relocalise(Frame* frame, std::vector<std::pair<int, int>>* matches,
                          FrameReport* report);
  // Starts a new segment at `frame`: its pose is restart_pose, its landmarks new ones.
  void Restart(const std::optional<Rigid3d>& restart_pose, Frame* frame,
               std::vector<std::pair<int, int>>* matches, FrameReport* report);
  // Carries the features' keyframe ancestry over the matches with `reference`.
  static void ChainTo(const Frame* reference, const std::vector<std::pair<int, int>>& matches,
                      Frame* frame);
  // The frame enters the map: observations of its tracked landmarks, new landmarks, place
  // recognition (loop closure or re-linking), local bundle adjustment.
  void AddKeyframe(Frame* frame, FrameReport* report);
  void AddNewLandmarks(Frame* frame, FrameReport* report);
  // Frees `keyframe` and the keyframes that share the most landmarks with it
  // (options_.local_window_frames in all); the others that see their landmarks stay fixed.
  void LocalBundleAdjustment(int keyframe, FrameReport* report);
  // Whether keyframe `keyframe` sees the place `frame` (a keyframe already stored) shows:
  // descriptor matches within vocabulary nodes, E on the bearings with the stereo scale (3D-3D
  // agreement), then the keyframe's landmarks confirmed in the frame at the pose that gives.
  std::optional<PlaceMatch> VerifyPlace(const Frame& frame, int keyframe);
  // Loop closure for a linked keyframe; returns whether the global adjustment ran.
  bool DetectLoop(Frame* frame, const BowVector& bow);
  // Re-linking of the open segment for one of its keyframes.
  void Relink(Frame* frame, const BowVector& bow, FrameReport* report);
  // Spreads the loop `match` of `frame` over the linked keyframes; moves the landmarks and the
  // other frames with their keyframes.
  void CorrectLoop(const Frame& frame, const PlaceMatch& match);
  // Links the frame's features to the landmarks the place match confirmed (merging landmarks
  // that were the same point seen twice).
  void FuseLandmarks(Frame* frame, const std::vector<std::pair<int, int>>& landmark_of_feature);
  void MergeLandmark(int from, int into);
  void SetLandmark(int frame_index, int camera, int feature, int landmark);
  // Global bundle adjustment over the linked keyframes after a loop correction.
  void AdjustLinkedKeyframes();
  // Non-keyframes follow their keyframes' poses.
  void PlaceNonKeyframes();
  // The saved map's keyframes (frames 0 .. first_frame_ - 1) and landmarks into the map, its
  // keyframes into the place recognition's database.
  void LoadMap(const SavedMap& saved);
  // The linked keyframes and the landmarks they see, for a later run (SlamResult::saved_map).
  SavedMap ExportSavedMap(const std::vector<FrameReport>& frames) const;
  bool IsSaved(int frame_index) const { return frame_index < first_frame_; }
  // The keyframes the adjustments may move: all but the saved map's.
  std::vector<int> FreeKeyframes(bool linked_only) const;
  // Whether the frame confirms enough of the saved map's landmarks to be localised in it.
  bool InSavedMap(const Frame& frame) const;

  const StereoRig& rig_;
  const SlamOptions& options_;
  const ProgressSink cancellation_;
  const Vocabulary& vocabulary_;
  SlamMap map_;
  std::optional<Frame> last_;  // the last tracked frame
  bool last_linked_ = false;
  Rigid3d last_step_;  // curr_from_prev of the last tracked step: the motion prior
  cv::Mat masks_[2];
  std::map<int, StoredKeyframe> keyframes_;  // by frame index
  std::vector<int> keyframe_order_;
  KeyframeDatabase database_;
  Frame* working_ = nullptr;  // the keyframe being added (SetLandmark updates it too)
  // Per frame: the keyframe a non-keyframe follows (-1: a keyframe or no pose) and its pose
  // relative to it; whether the frame is linked to the first frame's world.
  std::vector<int> keyframe_of_frame_;
  std::vector<Rigid3d> rig_from_keyframe_;
  std::vector<char> linked_;
  // The open (not yet linked) segment since the last re-initialisation.
  struct Segment {
    int first_frame = -1;
    int first_landmark = -1;
  };
  std::optional<Segment> segment_;
  std::vector<LoopReport> loops_;
  std::vector<PoseGraphEdge> loop_edges_;
  // With a saved map: its keyframes are frames 0 .. first_frame_ - 1 (their names in
  // saved_names_), its landmarks 0 .. num_saved_landmarks_ - 1.
  int first_frame_ = 0;
  int num_saved_landmarks_ = 0;
  std::vector<std::string> saved_names_;
};

}  // namespace omnirig::slam::internal
