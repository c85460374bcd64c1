#include "engine/slam/slam.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <exception>
#include <future>
#include <map>
#include <set>
#include <thread>

#include "engine/slam/pose_graph.h"
#include "engine/slam/vocabulary.h"
#include "engine/util/check.h"
#include "engine/util/timer.h"

namespace omnirig::slam {

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

namespace {

double CpuSeconds(clockid_t clock) {
  timespec now{};
  clock_gettime(clock, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

// Wall-clock and CPU time of one stage: the calling thread's CPU time (stages run on two
// threads at once), or the whole process's for a stage that owns the machine. On a shared
// machine the CPU time is the stable measure of the work; the wall time is what a user waits.
class StageClock {
 public:
  explicit StageClock(clockid_t clock = CLOCK_THREAD_CPUTIME_ID) : clock_(clock) { Restart(); }
  void Restart() {
    wall_.Restart();
    cpu_start_ = omnirig::slam::CpuSeconds(clock_);
  }
  void ChargeTo(double StageTimes::*stage, FrameReport* report) const {
    report->times.*stage += WallSeconds();
    report->cpu_times.*stage += CpuSeconds();
  }
  double WallSeconds() const { return wall_.ElapsedSeconds(); }
  double CpuSeconds() const { return omnirig::slam::CpuSeconds(clock_) - cpu_start_; }

 private:
  clockid_t clock_;
  Timer wall_;
  double cpu_start_ = 0;
};

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
  bool keyframe = false;
};

struct StoredKeyframe {
  Frame frame;
  BowVector bow;
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
cv::Mat FloatDescriptors(const cv::Mat& descriptors) {
  if (descriptors.type() == CV_32F) return descriptors;
  cv::Mat f;
  descriptors.convertTo(f, CV_32F);
  return f;
}

double RotationDeg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return a.angularDistance(b) * 180.0 / M_PI;
}

class Tracker {
 public:
  // `progress` is asked for cancellation only (inside the bundle adjustments); RunSlam
  // reports the frames.
  Tracker(const StereoRig& rig, const SlamOptions& options, const ProgressSink& progress)
      : rig_(rig),
        options_(options),
        cancellation_{nullptr, progress.is_cancelled},
        vocabulary_(DefaultVocabulary()) {}

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
  FrameReport BackEnd(FrontEndResult front, bool last_frame);
  // The end of the run: the global adjustment over the keyframes (into `result`), the other
  // frames placed relative to their keyframes, the loops and per-frame links into `result`.
  void Finish(const ProgressSink& progress, SlamResult* result);
  SlamMap& map() { return map_; }

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
  bool NeedsKeyframe(const Frame& frame, const FrameReport& report) const;
  // The frame enters the map: observations of its tracked landmarks, new landmarks, place
  // recognition (loop closure or re-linking), local bundle adjustment.
  void AddKeyframe(Frame* frame, FrameReport* report);
  void AddNewLandmarks(Frame* frame, FrameReport* report);
  void LocalBundleAdjustment(FrameReport* report);
  // Whether keyframe `keyframe` sees the place `frame` shows: descriptor matches, E on the
  // bearings with the stereo scale (3D-3D agreement), then the keyframe's landmarks confirmed
  // in the frame at the pose that gives.
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
  Frame* working_ = nullptr;         // the keyframe being added (SetLandmark updates it too)
  int last_keyframe_landmarks_ = 0;  // landmarks the last keyframe holds
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
};

bool Tracker::CheckImages(const StereoImages& images, FrameReport* report) {
  const cv::Mat* image[2] = {&images.cam0, &images.cam1};
  const CameraModel* camera[2] = {&rig_.cam0, &rig_.cam1};
  for (int c = 0; c < 2; ++c) {
    OMNIRIG_CHECK(image[c]->cols == camera[c]->width && image[c]->rows == camera[c]->height,
                  "frame " << report->name << ": cam" << c << " image is " << image[c]->cols
                           << "x" << image[c]->rows << " but the rig's calibration is "
                           << camera[c]->width << "x" << camera[c]->height);
  }
  for (int c = 0; c < 2; ++c) {
    // The mirror's disk does not move on a rig: find it once, on the first usable image.
    if (masks_[c].empty() && cv::mean(*image[c])[0] >= options_.min_mean_intensity) {
      const MirrorAnnulus annulus =
          EstimateMirrorAnnulus(*camera[c], *image[c], options_.features.dark_level);
      masks_[c] = MirrorMask(*camera[c], annulus, options_.features.mask_margin_px);
    }
    const double mean = masks_[c].empty() ? cv::mean(*image[c])[0]
                                          : MeanIntensity(*image[c], masks_[c]);
    if (mean < options_.min_mean_intensity) {
      report->reason = "cam" + std::to_string(c) + " image is black (mean grey level " +
                       std::to_string(static_cast<int>(mean)) + ")";
      return false;
    }
  }
  return true;
}

bool Tracker::DetectAndMatchStereo(const StereoImages& images, bool parallel_cameras,
                                   Frame* frame, FrameReport* report) {
  const cv::Mat* image[2] = {&images.cam0, &images.cam1};
  const CameraModel* camera[2] = {&rig_.cam0, &rig_.cam1};
  StageClock timer;
  if (!CheckImages(images, report)) {
    timer.ChargeTo(&StageTimes::detect_s, report);
    return false;
  }
  std::exception_ptr failure[2];
  double helper_cpu_s = 0;  // cam1's detection on its own thread
  auto detect = [&](int c) {
    try {
      frame->features[c] = DetectFeatures(*camera[c], *image[c], masks_[c], options_.features);
    } catch (...) {
      failure[c] = std::current_exception();
    }
  };
  if (parallel_cameras) {
    std::thread cam1_thread([&] {
      const StageClock cam1_timer;
      detect(1);
      helper_cpu_s = cam1_timer.CpuSeconds();
    });
    detect(0);
    cam1_thread.join();
  } else {
    detect(0);
    detect(1);
  }
  for (const std::exception_ptr& e : failure) {
    if (e) std::rethrow_exception(e);
  }
  report->cpu_times.detect_s += helper_cpu_s;
  timer.ChargeTo(&StageTimes::detect_s, report);
  for (int c = 0; c < 2; ++c) report->num_features[c] = frame->features[c].size();
  for (int c = 0; c < 2; ++c) {
    if (frame->features[c].size() < options_.min_features) {
      report->reason = "cam" + std::to_string(c) + ": too few features (" +
                       std::to_string(frame->features[c].size()) +
                       "): blurred, featureless or covered image";
      return false;
    }
  }
  timer.Restart();
  frame->stereo = MatchStereo(rig_, frame->features[0], frame->features[1], options_.stereo);
  frame->stereo_of_feature0.assign(frame->features[0].size(), -1);
  for (size_t s = 0; s < frame->stereo.size(); ++s) {
    frame->stereo_of_feature0[frame->stereo[s].feature0] = static_cast<int>(s);
  }
  report->num_stereo_points = static_cast<int>(frame->stereo.size());
  timer.ChargeTo(&StageTimes::stereo_s, report);
  if (report->num_stereo_points < options_.min_stereo_points) {
    report->reason = "too few stereo matches (" + std::to_string(report->num_stereo_points) + ")";
    return false;
  }
  return true;
}

bool Tracker::EstimateMotion(const Frame& reference, const Frame& frame,
                             const std::vector<std::pair<int, int>>& matches,
                             Rigid3d* curr_from_prev, FrameReport* report) {
  std::vector<Eigen::Vector3d> bearings_prev, bearings_curr;
  for (const auto& [a, b] : matches) {
    bearings_prev.push_back(reference.features[0].bearings[a]);
    bearings_curr.push_back(frame.features[0].bearings[b]);
  }
  EssentialRansacOptions essential = options_.essential;
  essential.seed = options_.essential.seed + static_cast<std::uint64_t>(frame.index);
  const EssentialReport e = EstimateEssentialRansac(bearings_prev, bearings_curr, essential);
  report->num_essential_inliers = e.num_inliers;
  std::vector<PointPair> pairs, inlier_pairs;
  for (size_t m = 0; m < matches.size(); ++m) {
    const int sa = reference.stereo_of_feature0[matches[m].first];
    const int sb = frame.stereo_of_feature0[matches[m].second];
    if (sa < 0 || sb < 0) continue;
    const PointPair pair{reference.stereo[sa].point_in_rig, frame.stereo[sb].point_in_rig,
                         reference.stereo[sa].range_std_m, frame.stereo[sb].range_std_m};
    pairs.push_back(pair);
    if (e.success && e.inlier_mask[m]) inlier_pairs.push_back(pair);
  }
  std::string why;
  if (e.success) {
    // The paper's path: R and the direction of t from E, |t| from the stereo points (eq. 18).
    const ScaleReport scale = EstimateScale(e.cam2_from_cam1.RotationMatrix(),
                                            e.cam2_from_cam1.translation, inlier_pairs,
                                            options_.scale);
    report->num_scale_inliers = scale.num_inliers;
    if (scale.success) {
      *curr_from_prev = Rigid3d(e.cam2_from_cam1.rotation, scale.translation_m);
      report->motion_source = "essential+scale";
      return true;
    }
    why = scale.reason;
  } else {
    why = "essential matrix: " + e.reason;
  }
  // E is degenerate without translation, and needs many matches: stereo points alone still
  // give the motion.
  ScaleOptions scale_options = options_.scale;
  scale_options.seed += static_cast<std::uint64_t>(frame.index);
  const AbsoluteOrientationReport rigid = EstimateRigidMotion3D(pairs, scale_options);
  if (rigid.success) {
    *curr_from_prev = rigid.curr_from_prev;
    report->num_scale_inliers = rigid.num_inliers;
    report->motion_source = "3d-3d";
    return true;
  }
  report->reason = why + "; " + rigid.reason;
  return false;
}

bool Tracker::TrackLandmarks(const Frame& reference, Frame* frame,
                             const std::vector<std::pair<int, int>>& matches,
                             FrameReport* report) {
  std::vector<Observation> observations;
  std::vector<Eigen::Vector3d> points;
  std::vector<int> landmark_ids;
  for (const auto& [a, b] : matches) {
    const int id = reference.landmark_of[0][a];
    if (id < 0 || !map_.landmarks[id].valid) continue;
    observations.push_back({frame->index, 0, b, frame->features[0].pixels[b]});
    points.push_back(map_.landmarks[id].point_in_world);
    landmark_ids.push_back(id);
    const int s = frame->stereo_of_feature0[b];
    if (s < 0) continue;
    const int f1 = frame->stereo[s].feature1;
    observations.push_back({frame->index, 1, f1, frame->features[1].pixels[f1]});
    points.push_back(map_.landmarks[id].point_in_world);
    landmark_ids.push_back(id);
  }
  std::vector<bool> inliers;
  Rigid3d& rig_from_world = map_.rig_from_world[frame->index];
  rig_from_world = RefineRigPose(rig_, rig_from_world, observations, points,
                                 options_.bundle_adjustment, &inliers);
  std::set<int> confirmed;
  for (size_t i = 0; i < observations.size(); ++i) {
    if (inliers[i]) confirmed.insert(landmark_ids[i]);
  }
  report->num_tracked_landmarks = static_cast<int>(confirmed.size());
  if (report->num_tracked_landmarks < options_.min_tracked_landmarks) {
    report->reason = "only " + std::to_string(report->num_tracked_landmarks) +
                     " map points confirmed in the new frame";
    return false;  // nothing linked
  }
  for (size_t i = 0; i < observations.size(); ++i) {
    if (!inliers[i]) continue;
    const Observation& o = observations[i];
    if (frame->landmark_of[o.camera][o.feature] >= 0) continue;  // one landmark per feature
    frame->landmark_of[o.camera][o.feature] = landmark_ids[i];
  }
  return true;
}

void Tracker::AddNewLandmarks(Frame* frame, FrameReport* report) {
  // The keyframe this one's features were tracked from: a new landmark whose feature it
  // holds without a landmark gains its observation there, when it reprojects.
  const auto chain = keyframes_.find(frame->chain_keyframe);
  Frame* previous = chain == keyframes_.end() ? nullptr : &chain->second.frame;
  const Rigid3d world_from_rig = map_.rig_from_world[frame->index].Inverse();
  const double max_sq = options_.bundle_adjustment.max_reprojection_error_px *
                        options_.bundle_adjustment.max_reprojection_error_px;
  for (const StereoPoint& sp : frame->stereo) {
    if (frame->landmark_of[0][sp.feature0] >= 0 || frame->landmark_of[1][sp.feature1] >= 0) {
      continue;
    }
    Landmark landmark;
    landmark.point_in_world = world_from_rig * sp.point_in_rig;
    landmark.rgb = frame->features[0].rgb[sp.feature0];
    landmark.observations.push_back(
        {frame->index, 0, sp.feature0, frame->features[0].pixels[sp.feature0]});
    landmark.observations.push_back(
        {frame->index, 1, sp.feature1, frame->features[1].pixels[sp.feature1]});
    const int id = static_cast<int>(map_.landmarks.size());
    const int a = previous ? frame->keyframe_feature_of[sp.feature0] : -1;
    if (a >= 0 && previous->landmark_of[0][a] < 0) {
      const Eigen::Vector3d in_previous =
          map_.rig_from_world[previous->index] * landmark.point_in_world;
      const auto pixel = Project(rig_.cam0.intrinsics, in_previous);
      if (pixel && (*pixel - previous->features[0].pixels[a]).squaredNorm() < max_sq) {
        landmark.observations.push_back(
            {previous->index, 0, a, previous->features[0].pixels[a]});
        previous->landmark_of[0][a] = id;
      }
    }
    frame->landmark_of[0][sp.feature0] = id;
    frame->landmark_of[1][sp.feature1] = id;
    map_.landmarks.push_back(std::move(landmark));
    ++report->num_new_landmarks;
  }
}

void Tracker::LocalBundleAdjustment(FrameReport* report) {
  if (options_.local_window_frames == 0 || keyframe_order_.size() < 2) return;
  const StageClock timer;
  const size_t n = std::min<size_t>(options_.local_window_frames, keyframe_order_.size());
  const std::vector<int> window(keyframe_order_.end() - n, keyframe_order_.end());
  // The window's landmarks, from the keyframes' own lists: no scan of the whole map.
  std::vector<int> landmarks;
  for (int keyframe : window) {
    const Frame& frame = keyframes_.at(keyframe).frame;
    for (const std::vector<int>& of : frame.landmark_of) {
      for (int id : of) {
        if (id >= 0) landmarks.push_back(id);
      }
    }
  }
  std::sort(landmarks.begin(), landmarks.end());
  landmarks.erase(std::unique(landmarks.begin(), landmarks.end()), landmarks.end());
  BundleAdjustmentOptions local = options_.bundle_adjustment;
  local.max_iterations = options_.local_max_iterations;
  // The other core runs the next frame's front end meanwhile.
  local.num_threads = 1;
  report->local_bundle_adjustment =
      BundleAdjustLandmarks(rig_, window, landmarks, local, &map_, cancellation_);
  timer.ChargeTo(&StageTimes::local_ba_s, report);
}

bool Tracker::TrackAgainst(const Frame& reference, Frame* frame,
                           std::vector<std::pair<int, int>>* matches, FrameReport* report) {
  for (int c = 0; c < 2; ++c) frame->landmark_of[c].assign(frame->features[c].size(), -1);
  StageClock timer;
  *matches = MatchDescriptorsGated(reference.features[0], frame->features[0],
                                   last_step_.RotationMatrix(), options_.temporal_gate_rad,
                                   options_.temporal_max_descriptor_ratio,
                                   options_.stereo.max_descriptor_distance);
  if (static_cast<int>(matches->size()) < options_.min_matches) {
    *matches = MatchDescriptors(reference.features[0].descriptors, frame->features[0].descriptors,
                                options_.temporal_max_descriptor_ratio,
                                options_.stereo.max_descriptor_distance);
  }
  report->num_matches = static_cast<int>(matches->size());
  timer.ChargeTo(&StageTimes::match_s, report);
  timer.Restart();
  bool tracked = false;
  Rigid3d curr_from_prev;
  if (report->num_matches < options_.min_matches) {
    report->reason = "too few matches with frame " + std::to_string(reference.index) + " (" +
                     std::to_string(report->num_matches) + ")";
  } else if (EstimateMotion(reference, *frame, *matches, &curr_from_prev, report)) {
    map_.rig_from_world[frame->index] = curr_from_prev * map_.rig_from_world[reference.index];
    tracked = TrackLandmarks(reference, frame, *matches, report);
  }
  timer.ChargeTo(&StageTimes::motion_s, report);
  return tracked;
}

Tracker::FrontEndResult Tracker::FrontEnd(int index, const std::string& name,
                                          const StereoFrameLoader& load, bool parallel_cameras) {
  FrontEndResult front;
  front.report.name = name;
  front.frame.index = index;
  const StageClock load_timer;
  const StereoImages images = load(index);
  load_timer.ChargeTo(&StageTimes::load_s, &front.report);
  front.usable = DetectAndMatchStereo(images, parallel_cameras, &front.frame, &front.report);
  return front;
}

FrameReport Tracker::BackEnd(FrontEndResult front, bool last_frame) {
  FrameReport report = std::move(front.report);
  Frame frame = std::move(front.frame);
  const int index = frame.index;
  map_.AddFrame();
  keyframe_of_frame_.push_back(-1);
  rig_from_keyframe_.emplace_back();
  linked_.push_back(0);
  OMNIRIG_CHECK(map_.has_pose.size() == static_cast<size_t>(index) + 1,
                "frames must reach the back end in order");
  if (!front.usable) {
    report.state = "lost";
    return report;
  }
  for (int c = 0; c < 2; ++c) frame.landmark_of[c].assign(frame.features[c].size(), -1);
  std::vector<std::pair<int, int>> matches;
  // Where a re-initialised frame starts: the motion estimate when there is one, else a
  // constant-velocity prediction from the last tracked frame.
  std::optional<Rigid3d> restart_pose;
  const Frame* reference = nullptr;
  if (last_) {
    restart_pose = last_step_ * map_.rig_from_world[last_->index];
    if (TrackAgainst(*last_, &frame, &matches, &report)) {
      reference = &*last_;
      report.linked = last_linked_;
      report.state = "tracked";
      last_step_ = map_.rig_from_world[index] * map_.rig_from_world[last_->index].Inverse();
    } else if (!report.motion_source.empty()) {
      restart_pose = map_.rig_from_world[index];
    }
  }
  if (!reference) reference = Relocalise(&frame, &matches, &report);
  if (!reference) Restart(restart_pose, &frame, &matches, &report);
  map_.has_pose[index] = true;
  ChainTo(reference, matches, &frame);
  frame.keyframe = report.state != "tracked" || last_frame || NeedsKeyframe(frame, report);
  if (frame.keyframe) {
    AddKeyframe(&frame, &report);
  } else {
    keyframe_of_frame_[index] = frame.chain_keyframe;
    rig_from_keyframe_[index] =
        map_.rig_from_world[index] * map_.rig_from_world[frame.chain_keyframe].Inverse();
  }
  report.keyframe = frame.keyframe;
  linked_[index] = report.linked;
  last_linked_ = report.linked;
  last_ = std::move(frame);
  return report;
}

void Tracker::ChainTo(const Frame* reference, const std::vector<std::pair<int, int>>& matches,
                      Frame* frame) {
  frame->keyframe_feature_of.assign(frame->features[0].size(), -1);
  frame->chain_keyframe = -1;
  if (!reference) return;
  frame->chain_keyframe = reference->keyframe ? reference->index : reference->chain_keyframe;
  for (const auto& [a, b] : matches) {
    frame->keyframe_feature_of[b] = reference->keyframe ? a : reference->keyframe_feature_of[a];
  }
}

bool Tracker::NeedsKeyframe(const Frame& frame, const FrameReport& report) const {
  if (frame.chain_keyframe < 0) return true;
  const Rigid3d keyframe_from_frame = map_.rig_from_world[frame.chain_keyframe] *
                                      map_.rig_from_world[frame.index].Inverse();
  return keyframe_from_frame.translation.norm() > options_.keyframe_max_distance_m ||
         RotationDeg(keyframe_from_frame.rotation, Eigen::Quaterniond::Identity()) >
             options_.keyframe_max_rotation_deg ||
         report.num_tracked_landmarks <
             options_.keyframe_min_tracked_fraction * last_keyframe_landmarks_;
}

void Tracker::AddKeyframe(Frame* frame, FrameReport* report) {
  const int index = frame->index;
  const StageClock map_timer;
  for (int c = 0; c < 2; ++c) {
    for (int f = 0; f < frame->features[c].size(); ++f) {
      const int id = frame->landmark_of[c][f];
      if (id < 0) continue;
      map_.landmarks[id].observations.push_back({index, c, f, frame->features[c].pixels[f]});
    }
  }
  AddNewLandmarks(frame, report);
  // The map's copy: cam0's features with byte descriptors, the stereo points, the links.
  StoredKeyframe& stored = keyframes_[index];
  stored.order = static_cast<int>(keyframe_order_.size());
  stored.linked = report->linked;
  if (!keyframe_order_.empty()) {
    const int previous = keyframe_order_.back();
    stored.path_m = keyframes_.at(previous).path_m +
                    (map_.rig_from_world[index].Inverse().translation -
                     map_.rig_from_world[previous].Inverse().translation)
                        .norm();
  }
  stored.frame.index = index;
  stored.frame.keyframe = true;
  stored.frame.features[0] = frame->features[0];
  frame->features[0].descriptors.convertTo(stored.frame.features[0].descriptors, CV_8U);
  stored.frame.stereo_of_feature0 = frame->stereo_of_feature0;
  stored.frame.stereo = frame->stereo;
  stored.frame.landmark_of[0] = frame->landmark_of[0];
  stored.frame.landmark_of[1] = frame->landmark_of[1];
  keyframe_order_.push_back(index);
  map_timer.ChargeTo(&StageTimes::map_s, report);

  const StageClock loop_timer;
  stored.bow = vocabulary_.Transform(frame->features[0].descriptors);
  working_ = frame;
  bool adjusted_globally = false;
  if (options_.loop_closure && report->linked) {
    adjusted_globally = DetectLoop(frame, stored.bow);
  } else if (options_.loop_closure && segment_ && index != segment_->first_frame) {
    Relink(frame, stored.bow, report);
  }
  working_ = nullptr;
  database_.Add(index, stored.bow);
  loop_timer.ChargeTo(&StageTimes::loop_s, report);
  const bool new_segment = report->state == "initialised" || report->state == "reinitialised";
  if (!adjusted_globally && !new_segment) LocalBundleAdjustment(report);
  last_keyframe_landmarks_ = 0;
  for (int id : frame->landmark_of[0]) last_keyframe_landmarks_ += id >= 0 ? 1 : 0;
}

const Frame* Tracker::Relocalise(Frame* frame, std::vector<std::pair<int, int>>* matches,
                                 FrameReport* report) {
  if (keyframes_.empty()) return nullptr;
  const StageClock timer;
  const BowVector bow = vocabulary_.Transform(frame->features[0].descriptors);
  const std::vector<KeyframeDatabase::Candidate> candidates = database_.Query(
      bow, [](int) { return true; }, options_.loop_min_score, options_.loop_max_candidates);
  const Frame* found = nullptr;
  for (const KeyframeDatabase::Candidate& candidate : candidates) {
    const StoredKeyframe& keyframe = keyframes_.at(candidate.keyframe);
    std::vector<std::pair<int, int>> keyframe_matches = MatchDescriptors(
        FloatDescriptors(keyframe.frame.features[0].descriptors), frame->features[0].descriptors,
        options_.temporal_max_descriptor_ratio, options_.stereo.max_descriptor_distance);
    std::vector<Eigen::Vector3d> bearings, points;
    for (const auto& [a, b] : keyframe_matches) {
      const int id = keyframe.frame.landmark_of[0][a];
      if (id < 0 || !map_.landmarks[id].valid) continue;
      bearings.push_back(frame->features[0].bearings[b]);
      points.push_back(map_.landmarks[id].point_in_world);
    }
    AbsolutePoseOptions absolute = options_.absolute_pose;
    absolute.seed += static_cast<std::uint64_t>(frame->index);
    const AbsolutePoseReport pose = EstimateAbsolutePose(bearings, points, absolute);
    if (!pose.success) continue;
    for (int c = 0; c < 2; ++c) frame->landmark_of[c].assign(frame->features[c].size(), -1);
    map_.rig_from_world[frame->index] = pose.rig_from_world;
    FrameReport attempt = *report;
    if (!TrackLandmarks(keyframe.frame, frame, keyframe_matches, &attempt)) continue;
    attempt.reason = "relocalised against frame " + std::to_string(candidate.keyframe) +
                     " (P3P, " + std::to_string(pose.num_inliers) + " inliers) after: " +
                     report->reason;
    attempt.state = "relocalised";
    attempt.motion_source = "p3p";
    attempt.num_matches = static_cast<int>(keyframe_matches.size());
    attempt.linked = keyframe.linked;
    *report = std::move(attempt);
    *matches = std::move(keyframe_matches);
    last_step_ = Rigid3d();  // the motion since the keyframe says nothing of the next step
    if (report->linked) segment_.reset();
    found = &keyframe.frame;
    break;
  }
  timer.ChargeTo(&StageTimes::loop_s, report);
  return found;
}

void Tracker::Restart(const std::optional<Rigid3d>& restart_pose, Frame* frame,
                      std::vector<std::pair<int, int>>* matches, FrameReport* report) {
  // The trajectory continues from the restart pose; the new landmarks are not tied to the old
  // ones until the segment recognises a mapped place.
  for (int c = 0; c < 2; ++c) frame->landmark_of[c].assign(frame->features[c].size(), -1);
  map_.rig_from_world[frame->index] = restart_pose.value_or(Rigid3d());
  matches->clear();
  last_step_ = Rigid3d();
  report->state = last_ ? "reinitialised" : "initialised";
  report->linked = !last_;
  if (last_) segment_ = Segment{frame->index, static_cast<int>(map_.landmarks.size())};
}
std::optional<PlaceMatch> Tracker::VerifyPlace(const Frame& frame, int keyframe) {
  const Frame& candidate = keyframes_.at(keyframe).frame;
  const std::vector<std::pair<int, int>> matches = MatchDescriptors(
      FloatDescriptors(candidate.features[0].descriptors), frame.features[0].descriptors,
      options_.temporal_max_descriptor_ratio, options_.stereo.max_descriptor_distance);
  if (static_cast<int>(matches.size()) < options_.loop_min_inliers) return std::nullopt;
  // On the sphere with the stereo scale: E's inliers must agree with the stereo points of both
  // frames in 3D (EstimateScale's consensus), not only on bearings.
  FrameReport scratch;
  Rigid3d frame_from_keyframe;
  if (!EstimateMotion(candidate, frame, matches, &frame_from_keyframe, &scratch) ||
      scratch.motion_source != "essential+scale" ||
      scratch.num_essential_inliers < options_.loop_min_inliers) {
    return std::nullopt;
  }
  // The keyframe's landmarks must then appear where that pose puts them, in both cameras.
  std::vector<Observation> observations;
  std::vector<Eigen::Vector3d> points;
  std::vector<int> landmark_ids;
  for (const auto& [a, b] : matches) {
    const int id = candidate.landmark_of[0][a];
    if (id < 0 || !map_.landmarks[id].valid) continue;
    observations.push_back({frame.index, 0, b, frame.features[0].pixels[b]});
    points.push_back(map_.landmarks[id].point_in_world);
    landmark_ids.push_back(id);
    const int s = frame.stereo_of_feature0[b];
    if (s < 0) continue;
    const int f1 = frame.stereo[s].feature1;
    observations.push_back({frame.index, 1, f1, frame.features[1].pixels[f1]});
    points.push_back(map_.landmarks[id].point_in_world);
    landmark_ids.push_back(id);
  }
  PlaceMatch match;
  match.keyframe = keyframe;
  std::vector<bool> inliers;
  match.rig_from_world =
      RefineRigPose(rig_, frame_from_keyframe * map_.rig_from_world[keyframe], observations,
                    points, options_.bundle_adjustment, &inliers);
  std::set<int> confirmed;
  for (size_t i = 0; i < observations.size(); ++i) {
    if (!inliers[i]) continue;
    confirmed.insert(landmark_ids[i]);
    if (observations[i].camera == 0) {
      match.landmark_of_feature.emplace_back(observations[i].feature, landmark_ids[i]);
    }
  }
  match.inliers = static_cast<int>(confirmed.size());
  if (match.inliers < options_.loop_min_inliers) return std::nullopt;
  return match;
}

bool Tracker::DetectLoop(Frame* frame, const BowVector& bow) {
  const StoredKeyframe& current = keyframes_.at(frame->index);
  const Eigen::Vector3d position = map_.rig_from_world[frame->index].Inverse().translation;
  // Only keyframes that tracking's estimate, drift allowed for, puts near enough to pass the
  // distance rule after verification.
  auto accept = [&](int keyframe) {
    const StoredKeyframe& stored = keyframes_.at(keyframe);
    if (!stored.linked || stored.order + options_.loop_min_keyframe_gap >= current.order) {
      return false;
    }
    const double reach = options_.loop_max_distance_m +
                         options_.loop_max_drift_fraction * (current.path_m - stored.path_m);
    return (map_.rig_from_world[keyframe].Inverse().translation - position).norm() <= reach;
  };
  for (const KeyframeDatabase::Candidate& candidate : database_.Query(
           bow, accept, options_.loop_min_score, options_.loop_max_candidates)) {
    const std::optional<PlaceMatch> match = VerifyPlace(*frame, candidate.keyframe);
    if (!match) continue;
    const Rigid3d frame_from_keyframe =
        match->rig_from_world * map_.rig_from_world[candidate.keyframe].Inverse();
    if (frame_from_keyframe.translation.norm() > options_.loop_max_distance_m) continue;
    const Rigid3d& before = map_.rig_from_world[frame->index];
    LoopReport loop;
    loop.frame_index = frame->index;
    loop.matched_frame_index = candidate.keyframe;
    loop.inliers = match->inliers;
    loop.correction_m = (before.Inverse().translation -
                         match->rig_from_world.Inverse().translation).norm();
    loop.correction_deg = RotationDeg(before.rotation, match->rig_from_world.rotation);
    loop.pose_graph = loop.correction_m > options_.loop_min_correction_m ||
                      loop.correction_deg > options_.loop_min_correction_deg;
    loop_edges_.push_back({candidate.keyframe, frame->index, frame_from_keyframe});
    if (loop.pose_graph) CorrectLoop(*frame, *match);
    FuseLandmarks(frame, match->landmark_of_feature);
    if (loop.pose_graph) AdjustLinkedKeyframes();
    loops_.push_back(loop);
    return loop.pose_graph;
  }
  return false;
}

void Tracker::Relink(Frame* frame, const BowVector& bow, FrameReport* report) {
  auto accept = [&](int keyframe) { return keyframes_.at(keyframe).linked; };
  for (const KeyframeDatabase::Candidate& candidate : database_.Query(
           bow, accept, options_.loop_min_score, options_.loop_max_candidates)) {
    const std::optional<PlaceMatch> match = VerifyPlace(*frame, candidate.keyframe);
    if (!match) continue;
    // world_from_segment_world: the segment's poses and landmarks into the map's world.
    const Rigid3d map_from_segment =
        match->rig_from_world.Inverse() * map_.rig_from_world[frame->index];
    const Rigid3d segment_from_map = map_from_segment.Inverse();
    for (int f = segment_->first_frame; f <= frame->index; ++f) {
      if (!map_.has_pose[f]) continue;
      map_.rig_from_world[f] = map_.rig_from_world[f] * segment_from_map;
      linked_[f] = 1;
      const auto stored = keyframes_.find(f);
      if (stored != keyframes_.end()) stored->second.linked = true;
    }
    for (size_t id = segment_->first_landmark; id < map_.landmarks.size(); ++id) {
      map_.landmarks[id].point_in_world = map_from_segment * map_.landmarks[id].point_in_world;
    }
    FuseLandmarks(frame, match->landmark_of_feature);
    report->reason = "segment from frame " + std::to_string(segment_->first_frame) +
                     " relinked through frame " + std::to_string(candidate.keyframe) + " (" +
                     std::to_string(match->inliers) + " landmarks)";
    report->state = "relinked";
    report->linked = true;
    segment_.reset();
    return;
  }
}

void Tracker::CorrectLoop(const Frame& frame, const PlaceMatch& match) {
  std::map<int, Rigid3d> poses;
  std::vector<PoseGraphEdge> edges = loop_edges_;
  int previous = -1;
  for (int keyframe : keyframe_order_) {
    if (!keyframes_.at(keyframe).linked) continue;
    poses[keyframe] = map_.rig_from_world[keyframe];
    if (previous >= 0) {
      edges.push_back({previous, keyframe,
                       map_.rig_from_world[keyframe] * map_.rig_from_world[previous].Inverse()});
    }
    previous = keyframe;
  }
  OMNIRIG_CHECK(poses.count(frame.index) && poses.count(match.keyframe),
                "loop between keyframes outside the map");
  const std::map<int, Rigid3d> before = poses;
  OptimisePoseGraph(edges, {poses.begin()->first}, options_.num_threads, &poses);
  for (const auto& [keyframe, pose] : poses) map_.rig_from_world[keyframe] = pose;
  // Each landmark moves with the keyframe that first observed it.
  for (Landmark& landmark : map_.landmarks) {
    if (!landmark.valid || landmark.observations.empty()) continue;
    const auto it = before.find(landmark.observations.front().frame);
    if (it == before.end()) continue;
    landmark.point_in_world =
        poses.at(it->first).Inverse() * (it->second * landmark.point_in_world);
  }
  PlaceNonKeyframes();
}

void Tracker::FuseLandmarks(Frame* frame,
                            const std::vector<std::pair<int, int>>& landmark_of_feature) {
  for (const auto& [feature, landmark] : landmark_of_feature) {
    if (!map_.landmarks[landmark].valid) continue;
    const int current = frame->landmark_of[0][feature];
    if (current == landmark) continue;
    if (current >= 0) {
      MergeLandmark(current, landmark);
      continue;
    }
    map_.landmarks[landmark].observations.push_back(
        {frame->index, 0, feature, frame->features[0].pixels[feature]});
    SetLandmark(frame->index, 0, feature, landmark);
    const int s = frame->stereo_of_feature0[feature];
    if (s < 0 || frame->landmark_of[1][frame->stereo[s].feature1] >= 0) continue;
    const int f1 = frame->stereo[s].feature1;
    map_.landmarks[landmark].observations.push_back(
        {frame->index, 1, f1, frame->features[1].pixels[f1]});
    SetLandmark(frame->index, 1, f1, landmark);
  }
}

void Tracker::MergeLandmark(int from, int into) {
  Landmark& source = map_.landmarks[from];
  Landmark& target = map_.landmarks[into];
  for (const Observation& o : source.observations) {
    const bool seen = std::any_of(
        target.observations.begin(), target.observations.end(),
        [&](const Observation& t) { return t.frame == o.frame && t.camera == o.camera; });
    if (seen) continue;
    target.observations.push_back(o);
    SetLandmark(o.frame, o.camera, o.feature, into);
  }
  source.observations.clear();
  source.valid = false;
}

void Tracker::SetLandmark(int frame_index, int camera, int feature, int landmark) {
  if (working_ && working_->index == frame_index) working_->landmark_of[camera][feature] = landmark;
  const auto stored = keyframes_.find(frame_index);
  if (stored != keyframes_.end()) stored->second.frame.landmark_of[camera][feature] = landmark;
}

void Tracker::AdjustLinkedKeyframes() {
  std::vector<int> linked;
  for (int keyframe : keyframe_order_) {
    if (keyframes_.at(keyframe).linked) linked.push_back(keyframe);
  }
  BundleAdjustmentOptions global = options_.bundle_adjustment;
  global.num_threads = options_.num_threads;
  BundleAdjust(rig_, linked, global, &map_, cancellation_);
  PlaceNonKeyframes();
}

void Tracker::PlaceNonKeyframes() {
  for (size_t f = 0; f < keyframe_of_frame_.size(); ++f) {
    const int keyframe = keyframe_of_frame_[f];
    if (keyframe < 0 || !map_.has_pose[f]) continue;
    map_.rig_from_world[f] = rig_from_keyframe_[f] * map_.rig_from_world[keyframe];
  }
}

std::vector<MapPoint> ExportMap(const SlamMap& map, int min_frames) {
  std::vector<MapPoint> points;
  for (const Landmark& landmark : map.landmarks) {
    if (!landmark.valid || landmark.observations.size() < 2) continue;
    std::set<int> frames;
    for (const Observation& o : landmark.observations) frames.insert(o.frame);
    if (static_cast<int>(frames.size()) < min_frames) continue;
    points.push_back({landmark.point_in_world, landmark.rgb,
                      static_cast<int>(landmark.observations.size())});
  }
  return points;
}

// The global bundle adjustment over `keyframes` (with the calibration refinement when options
// ask for it), into result's global_bundle_adjustment, calibration_refinement and times.
void GlobalBundleAdjustment(const StereoRig& rig, const SlamOptions& options,
                            const std::vector<int>& keyframes, const ProgressSink& progress,
                            SlamMap* map, SlamResult* result) {
  if (options.global_bundle_adjustment && keyframes.size() >= 2) {
    progress.ThrowIfCancelled();
    progress.Report(0.95, "global_ba", "global bundle adjustment");
    BundleAdjustmentOptions global = options.bundle_adjustment;
    global.max_iterations = std::max(global.max_iterations, 50);
    global.num_threads = options.num_threads;
    const ProgressSink ba_progress{
        [&](double fraction, const std::string& stage, const std::string& message) {
          progress.Report(0.95 + 0.04 * fraction, stage, "global bundle adjustment: " + message);
        },
        progress.is_cancelled};
    const StageClock ba_timer(CLOCK_PROCESS_CPUTIME_ID);
    if (options.calibration_refinement.refine == CalibrationRefinement::kNone) {
      result->global_bundle_adjustment = BundleAdjust(rig, keyframes, global, map, ba_progress);
    } else {
      StereoRig refined = rig;
      result->calibration_refinement.emplace();
      result->global_bundle_adjustment =
          BundleAdjustWithCalibration(options.calibration_refinement, keyframes, global,
                                      &refined, map, &*result->calibration_refinement,
                                      ba_progress);
    }
    result->global_ba_s = ba_timer.WallSeconds();
    result->global_ba_cpu_s = ba_timer.CpuSeconds();
  }
  if (options.calibration_refinement.refine != CalibrationRefinement::kNone &&
      !result->calibration_refinement) {
    CalibrationRefinementReport& refusal = result->calibration_refinement.emplace();
    refusal.refine = options.calibration_refinement.refine;
    refusal.before = refusal.after = rig;
    refusal.num_frames = static_cast<int>(keyframes.size());
    refusal.reason = "no global bundle adjustment: " + std::to_string(keyframes.size()) +
                     " tracked frame(s) in the map";
  }
}

void Tracker::Finish(const ProgressSink& progress, SlamResult* result) {
  GlobalBundleAdjustment(rig_, options_, keyframe_order_, progress, &map_, result);
  PlaceNonKeyframes();
  result->num_keyframes = static_cast<int>(keyframe_order_.size());
  for (size_t i = 0; i < result->frames.size(); ++i) {
    FrameReport& frame = result->frames[i];
    frame.linked = linked_[i] != 0;
    if (!map_.has_pose[i]) {
      ++result->num_lost;
      continue;
    }
    ++result->num_tracked;
    frame.world_from_rig = map_.rig_from_world[i].Inverse();
  }
  result->loops = loops_;
  for (LoopReport& loop : result->loops) {
    loop.frame = result->frames[loop.frame_index].name;
    loop.matched_frame = result->frames[loop.matched_frame_index].name;
  }
  result->map = ExportMap(map_, options_.min_map_point_frames);
}

}  // namespace

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
