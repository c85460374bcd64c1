#include "engine/slam/slam.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <future>
#include <exception>
#include <set>
#include <thread>

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
}

void StageTimes::Add(const StageTimes& o) {
  load_s += o.load_s;
  detect_s += o.detect_s;
  stereo_s += o.stereo_s;
  match_s += o.match_s;
  motion_s += o.motion_s;
  map_s += o.map_s;
  local_ba_s += o.local_ba_s;
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

// Everything kept of the last tracked frame for matching the next one.
struct KeyFrame {
  int index = -1;
  CameraFeatures features[2];
  std::vector<int> stereo_of_feature0;  // index into `stereo`, -1 when none
  std::vector<StereoPoint> stereo;
  std::vector<int> landmark_of[2];      // per feature, -1 when none
};

class Tracker {
 public:
  // `progress` is asked for cancellation only (inside the local bundle adjustment); RunSlam
  // reports the frames.
  Tracker(const StereoRig& rig, const SlamOptions& options, const ProgressSink& progress)
      : rig_(rig), options_(options), cancellation_{nullptr, progress.is_cancelled} {}

  // The per-frame half that needs no map: load, mask, features, stereo points. Runs one frame
  // ahead of BackEnd() on a worker thread; never two FrontEnd() calls at once.
  struct FrontEndResult {
    KeyFrame frame;
    FrameReport report;
    bool usable = false;
  };
  FrontEndResult FrontEnd(int index, const std::string& name, const StereoFrameLoader& load,
                          bool parallel_cameras);
  // Tracking against the map, map update, local bundle adjustment.
  FrameReport BackEnd(FrontEndResult front);
  SlamMap& map() { return map_; }

 private:
  // Checks the image sizes (throws), finds the mirror masks on the first usable images, and
  // returns false (with report->reason) for a black image.
  bool CheckImages(const StereoImages& images, FrameReport* report);
  // Returns false (with report->reason) when the frame has too little to work with.
  bool DetectAndMatchStereo(const StereoImages& images, bool parallel_cameras, KeyFrame* frame,
                            FrameReport* report);
  // Matches `frame` with `reference` (a tracked keyframe), estimates the motion between them
  // and refines the pose against the reference's landmarks. `matches` are (reference feature,
  // frame feature) in cam0; false with report->reason on failure.
  bool TrackAgainst(const KeyFrame& reference, bool use_motion_prior, KeyFrame* frame,
                    std::vector<std::pair<int, int>>* matches, FrameReport* report);
  // Estimates curr_from_prev with E + scale (or 3D-3D); false with the reason on failure.
  bool EstimateMotion(const KeyFrame& reference, const KeyFrame& frame,
                      const std::vector<std::pair<int, int>>& matches, Rigid3d* curr_from_prev,
                      FrameReport* report);
  // Refines the new pose against the landmarks of the reference frame; links confirmed ones.
  bool TrackLandmarks(const KeyFrame& reference, KeyFrame* frame,
                      const std::vector<std::pair<int, int>>& matches, FrameReport* report);
  // `reference` is null for a frame that starts a new segment.
  void AddNewLandmarks(const KeyFrame* reference, KeyFrame* frame,
                       const std::vector<std::pair<int, int>>& matches, FrameReport* report);
  void LocalBundleAdjustment(FrameReport* report);
  // Tracks `frame` against anchor_ without the motion prior (the motion since then is
  // unknown); on success replaces `report` and `matches`.
  bool Relocalise(KeyFrame* frame, std::vector<std::pair<int, int>>* matches, FrameReport* report);
  // Starts a new segment at `frame`: its pose is restart_pose, its landmarks new ones.
  void Restart(const std::optional<Rigid3d>& restart_pose, KeyFrame* frame,
               std::vector<std::pair<int, int>>* matches, FrameReport* report);

  const StereoRig& rig_;
  const SlamOptions& options_;
  const ProgressSink cancellation_;
  SlamMap map_;
  std::optional<KeyFrame> last_;
  bool last_linked_ = false;  // last_ is in the first frame's world through tracked frames
  // The last linked keyframe once a re-initialisation has replaced it as last_: frames that
  // cannot be tracked against last_ try it before re-initialising (relocalisation).
  std::optional<KeyFrame> anchor_;
  Rigid3d last_step_;  // curr_from_prev of the last tracked step: the motion prior
  cv::Mat masks_[2];
  std::vector<int> tracked_frames_;
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
                                   KeyFrame* frame, FrameReport* report) {
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

bool Tracker::EstimateMotion(const KeyFrame& reference, const KeyFrame& frame,
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

bool Tracker::TrackLandmarks(const KeyFrame& reference, KeyFrame* frame,
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
    return false;  // nothing linked: the frame re-initialises
  }
  for (size_t i = 0; i < observations.size(); ++i) {
    if (!inliers[i]) continue;
    const Observation& o = observations[i];
    if (frame->landmark_of[o.camera][o.feature] >= 0) continue;  // one landmark per feature
    frame->landmark_of[o.camera][o.feature] = landmark_ids[i];
    map_.landmarks[landmark_ids[i]].observations.push_back(o);
  }
  return true;
}

void Tracker::AddNewLandmarks(const KeyFrame* reference, KeyFrame* frame,
                              const std::vector<std::pair<int, int>>& matches,
                              FrameReport* report) {
  std::vector<int> prev_of_feature0(frame->features[0].size(), -1);
  for (const auto& [a, b] : matches) prev_of_feature0[b] = a;
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
    landmark.observations.push_back({frame->index, 0, sp.feature0, frame->features[0].pixels[sp.feature0]});
    landmark.observations.push_back({frame->index, 1, sp.feature1, frame->features[1].pixels[sp.feature1]});
    const int id = static_cast<int>(map_.landmarks.size());
    // The same feature in the last frame, if it did not belong to a landmark yet and agrees.
    const int a = prev_of_feature0[sp.feature0];
    if (reference && a >= 0 && reference->landmark_of[0][a] < 0) {
      const Eigen::Vector3d in_prev =
          map_.rig_from_world[reference->index] * landmark.point_in_world;
      const auto pixel = Project(rig_.cam0.intrinsics, in_prev);
      if (pixel && (*pixel - reference->features[0].pixels[a]).squaredNorm() < max_sq) {
        landmark.observations.push_back(
            {reference->index, 0, a, reference->features[0].pixels[a]});
      }
    }
    frame->landmark_of[0][sp.feature0] = id;
    frame->landmark_of[1][sp.feature1] = id;
    map_.landmarks.push_back(std::move(landmark));
    ++report->num_new_landmarks;
  }
}

void Tracker::LocalBundleAdjustment(FrameReport* report) {
  if (options_.local_window_frames == 0 || tracked_frames_.size() < 2) return;
  const StageClock timer;
  const size_t n = std::min<size_t>(options_.local_window_frames, tracked_frames_.size());
  std::vector<int> window(tracked_frames_.end() - n, tracked_frames_.end());
  BundleAdjustmentOptions local = options_.bundle_adjustment;
  local.max_iterations = options_.local_max_iterations;
  // The other core runs the next frame's front end meanwhile.
  local.num_threads = 1;
  report->local_bundle_adjustment = BundleAdjust(rig_, window, local, &map_, cancellation_);
  timer.ChargeTo(&StageTimes::local_ba_s, report);
}

bool Tracker::TrackAgainst(const KeyFrame& reference, bool use_motion_prior, KeyFrame* frame,
                           std::vector<std::pair<int, int>>* matches, FrameReport* report) {
  for (int c = 0; c < 2; ++c) frame->landmark_of[c].assign(frame->features[c].size(), -1);
  StageClock timer;
  matches->clear();
  if (use_motion_prior) {
    *matches = MatchDescriptorsGated(reference.features[0], frame->features[0],
                                     last_step_.RotationMatrix(), options_.temporal_gate_rad,
                                     options_.temporal_max_descriptor_ratio,
                                     options_.stereo.max_descriptor_distance);
  }
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

FrameReport Tracker::BackEnd(FrontEndResult front) {
  FrameReport report = std::move(front.report);
  KeyFrame frame = std::move(front.frame);
  const int index = frame.index;
  map_.AddFrame();
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
  const KeyFrame* reference = nullptr;
  if (last_) {
    restart_pose = last_step_ * map_.rig_from_world[last_->index];
    if (TrackAgainst(*last_, /*use_motion_prior=*/true, &frame, &matches, &report)) {
      reference = &*last_;
      report.linked = last_linked_;
    } else if (!report.motion_source.empty()) {
      restart_pose = map_.rig_from_world[index];
    }
  }
  if (!reference && anchor_ && !last_linked_ && Relocalise(&frame, &matches, &report)) {
    reference = &*anchor_;
  }
  const StageClock map_timer;
  if (!reference) {
    Restart(restart_pose, &frame, &matches, &report);
  } else {
    last_step_ = map_.rig_from_world[index] * map_.rig_from_world[reference->index].Inverse();
    report.state = reference == &*last_ ? "tracked" : "relocalised";
  }
  map_.has_pose[index] = true;
  AddNewLandmarks(reference, &frame, matches, &report);
  map_timer.ChargeTo(&StageTimes::map_s, &report);
  tracked_frames_.push_back(index);
  if (reference) LocalBundleAdjustment(&report);
  last_linked_ = report.linked;
  last_ = std::move(frame);
  return report;
}

bool Tracker::Relocalise(KeyFrame* frame, std::vector<std::pair<int, int>>* matches,
                         FrameReport* report) {
  FrameReport attempt = *report;
  attempt.reason.clear();
  attempt.motion_source.clear();
  std::vector<std::pair<int, int>> anchor_matches;
  if (!TrackAgainst(*anchor_, /*use_motion_prior=*/false, frame, &anchor_matches, &attempt)) {
    return false;
  }
  attempt.reason =
      "relocalised against frame " + std::to_string(anchor_->index) + " after: " + report->reason;
  *report = std::move(attempt);
  *matches = std::move(anchor_matches);
  report->linked = true;
  return true;
}

void Tracker::Restart(const std::optional<Rigid3d>& restart_pose, KeyFrame* frame,
                      std::vector<std::pair<int, int>>* matches, FrameReport* report) {
  // The trajectory continues from the restart pose; the new landmarks are not tied to the old
  // ones.
  for (int c = 0; c < 2; ++c) frame->landmark_of[c].assign(frame->features[c].size(), -1);
  map_.rig_from_world[frame->index] = restart_pose.value_or(Rigid3d());
  matches->clear();
  last_step_ = Rigid3d();
  report->state = last_ ? "reinitialised" : "initialised";
  report->linked = !last_;
  if (last_ && last_linked_) anchor_ = std::move(last_);
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

// The global bundle adjustment over every tracked frame (with the calibration refinement when
// options ask for it), into result's global_bundle_adjustment, calibration_refinement and times.
void GlobalBundleAdjustment(const StereoRig& rig, const SlamOptions& options,
                            const ProgressSink& progress, SlamMap* map, SlamResult* result) {
  std::vector<int> all_frames;
  for (int i = 0; i < static_cast<int>(map->has_pose.size()); ++i) {
    if (map->has_pose[i]) all_frames.push_back(i);
  }
  if (options.global_bundle_adjustment && all_frames.size() >= 2) {
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
      result->global_bundle_adjustment = BundleAdjust(rig, all_frames, global, map, ba_progress);
    } else {
      StereoRig refined = rig;
      result->calibration_refinement.emplace();
      result->global_bundle_adjustment =
          BundleAdjustWithCalibration(options.calibration_refinement, all_frames, global,
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
    refusal.num_frames = static_cast<int>(all_frames.size());
    refusal.reason = "no global bundle adjustment: " + std::to_string(all_frames.size()) +
                     " tracked frame(s)";
  }
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
    FrameReport report = tracker.BackEnd(std::move(front));
    result.stage_totals.Add(report.times);
    result.cpu_stage_totals.Add(report.cpu_times);
    progress.Report(0.95 * (i + 1) / n, "track",
                    "frame " + std::to_string(i + 1) + "/" + std::to_string(n) + " " +
                        frame_names[i] + ": " + report.state +
                        (report.reason.empty() ? "" : " (" + report.reason + ")"));
    result.frames.push_back(std::move(report));
  }
  SlamMap& map = tracker.map();
  GlobalBundleAdjustment(rig, options, progress, &map, &result);
  for (int i = 0; i < n; ++i) {
    if (!map.has_pose[i]) {
      ++result.num_lost;
      continue;
    }
    ++result.num_tracked;
    result.frames[i].world_from_rig = map.rig_from_world[i].Inverse();
  }
  result.map = ExportMap(map, options.min_map_point_frames);
  result.total_s = total.WallSeconds();
  result.total_cpu_s = total.CpuSeconds();
  progress.Report(1.0, "done", std::to_string(result.num_tracked) + " of " + std::to_string(n) +
                                   " frames tracked, " + std::to_string(result.map.size()) +
                                   " map points");
  return result;
}

}  // namespace omnirig::slam
