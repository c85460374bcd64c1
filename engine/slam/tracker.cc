#include "engine/slam/tracker.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <set>
#include <thread>

#include "engine/util/check.h"

namespace omnirig::slam::internal {

double CpuSeconds(clockid_t clock) {
  timespec now{};
  clock_gettime(clock, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

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
      masks_[c] = MirrorMask(*image[c], PrincipalPoint(*camera[c]), options_.features.mirror_mask);
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
  frame->stereo = MatchStereo(rig_.cam0_from_cam1, frame->features[0], frame->features[1],
                              options_.stereo.Matching(), options_.stereo.Triangulation(rig_))
                      .points;
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
    const PointPair pair{reference.stereo[sa].point_in_cam0, frame.stereo[sb].point_in_cam0,
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
                             const std::vector<std::pair<int, int>>& matches, FrameReport* report) {
  std::vector<std::pair<int, int>> landmark_of_feature;
  for (const auto& [a, b] : matches) {
    const int id = reference.landmark_of[0][a];
    if (id >= 0 && map_.landmarks[id].valid) landmark_of_feature.emplace_back(b, id);
  }
  return RefineAgainstLandmarks(landmark_of_feature, frame, report);
}

bool Tracker::RefineAgainstLandmarks(const std::vector<std::pair<int, int>>& landmark_of_feature,
                                     Frame* frame, FrameReport* report) {
  std::vector<Observation> observations;
  std::vector<Eigen::Vector3d> points;
  std::vector<int> landmark_ids;
  for (const auto& [b, id] : landmark_of_feature) {
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

std::vector<std::pair<int, int>> Tracker::CovisibleKeyframes(
    const std::vector<int>& landmark_of) const {
  std::map<int, int> shared;  // by keyframe
  for (int id : landmark_of) {
    if (id < 0 || !map_.landmarks[id].valid) continue;
    for (const Observation& o : map_.landmarks[id].observations) {
      if (o.camera == 0) ++shared[o.frame];
    }
  }
  std::vector<std::pair<int, int>> keyframes(shared.begin(), shared.end());
  // Most shared first; among equals the most recent.
  std::sort(keyframes.begin(), keyframes.end(), [](const auto& a, const auto& b) {
    return a.second != b.second ? a.second > b.second : a.first > b.first;
  });
  return keyframes;
}

std::vector<std::pair<int, int>> Tracker::MatchKeyframeLandmarks(int keyframe,
                                                                 const Frame& frame) const {
  const Frame& stored = keyframes_.at(keyframe).frame;
  const Rigid3d& rig_from_world = map_.rig_from_world[frame.index];
  // The keyframe's landmarks as features seen from the frame: the bearing its pose predicts
  // (the rig frame is cam0's), the keyframe's descriptor.
  CameraFeatures predicted;
  std::vector<int> landmark_ids;
  std::vector<int> rows;
  for (int f = 0; f < stored.features[0].size(); ++f) {
    const int id = stored.landmark_of[0][f];
    if (id < 0 || !map_.landmarks[id].valid) continue;
    const Eigen::Vector3d point_in_rig = rig_from_world * map_.landmarks[id].point_in_world;
    if (point_in_rig.norm() < 1e-6) continue;
    predicted.pixels.push_back(stored.features[0].pixels[f]);
    predicted.bearings.push_back(point_in_rig.normalized());
    landmark_ids.push_back(id);
    rows.push_back(f);
  }
  predicted.descriptors.create(static_cast<int>(rows.size()), stored.features[0].descriptors.cols,
                               CV_32F);
  for (size_t r = 0; r < rows.size(); ++r) {
    stored.features[0].descriptors.row(rows[r]).convertTo(
        predicted.descriptors.row(static_cast<int>(r)), CV_32F);
  }
  std::vector<std::pair<int, int>> landmark_of_feature;
  for (const auto& [a, b] : MatchDescriptorsGated(
           predicted, frame.features[0], Eigen::Matrix3d::Identity(), options_.map_gate_rad,
           options_.temporal_max_descriptor_ratio, options_.stereo.max_descriptor_distance)) {
    if (frame.landmark_of[0][b] < 0) landmark_of_feature.emplace_back(b, landmark_ids[a]);
  }
  return landmark_of_feature;
}

void Tracker::TrackLocalMap(Frame* frame, FrameReport* report) {
  StageClock timer;
  std::vector<std::pair<int, int>> covisible = CovisibleKeyframes(frame->landmark_of[0]);
  std::set<int> known;  // landmarks the frame holds or gained here
  std::vector<std::pair<int, int>> landmark_of_feature;
  for (int f = 0; f < frame->features[0].size(); ++f) {
    const int id = frame->landmark_of[0][f];
    if (id >= 0 && map_.landmarks[id].valid && known.insert(id).second) {
      landmark_of_feature.emplace_back(f, id);
    }
  }
  const size_t tracked = landmark_of_feature.size();
  std::vector<char> feature_taken(frame->features[0].size(), 0);
  for (const auto& [f, id] : landmark_of_feature) feature_taken[f] = 1;
  // The keyframes of an earlier passage among them: on a first passage the frame tracks the
  // recent keyframes' landmarks from the last frame already.
  int num_local = 0;
  for (const auto& [keyframe, shared] : covisible) {
    if (num_local == options_.local_map_keyframes) break;
    if (KeyframesSince(keyframe) <= options_.loop_min_keyframe_gap) continue;
    ++num_local;
    for (const auto& [f, id] : MatchKeyframeLandmarks(keyframe, *frame)) {
      if (feature_taken[f] || !known.insert(id).second) continue;
      feature_taken[f] = 1;
      landmark_of_feature.emplace_back(f, id);
    }
  }
  timer.ChargeTo(&StageTimes::match_s, report);
  timer.Restart();
  if (landmark_of_feature.size() > tracked) {
    // Refined against all of them; the frame keeps what it had if that fails.
    const Rigid3d before = map_.rig_from_world[frame->index];
    const std::vector<int> landmark_of[2] = {frame->landmark_of[0], frame->landmark_of[1]};
    for (int c = 0; c < 2; ++c) frame->landmark_of[c].assign(frame->features[c].size(), -1);
    FrameReport attempt = *report;
    if (RefineAgainstLandmarks(landmark_of_feature, frame, &attempt)) {
      report->num_tracked_landmarks = attempt.num_tracked_landmarks;
      covisible = CovisibleKeyframes(frame->landmark_of[0]);
    } else {
      map_.rig_from_world[frame->index] = before;
      for (int c = 0; c < 2; ++c) frame->landmark_of[c] = landmark_of[c];
    }
  }
  DecideKeyframe(covisible, frame, *report);
  timer.ChargeTo(&StageTimes::motion_s, report);
}

KeyframeDecision DecideKeyframe(const std::vector<CovisibleKeyframe>& covisible,
                                int num_tracked_landmarks, const SlamOptions& options) {
  KeyframeDecision decision;
  if (covisible.empty()) return decision;
  auto near = [&](const CovisibleKeyframe& k) {
    return k.keyframe_from_frame.translation.norm() <= options.keyframe_max_distance_m &&
           RotationDeg(k.keyframe_from_frame.rotation, Eigen::Quaterniond::Identity()) <=
               options.keyframe_max_rotation_deg;
  };
  // A keyframe of an earlier passage (older than the loop candidates' gap) near the frame, of
  // whose landmarks the frame tracks enough: the map covers the view.
  for (const CovisibleKeyframe& k : covisible) {
    if (k.shared < options.keyframe_min_mapped_landmarks) break;
    if (k.keyframes_since <= options.loop_min_keyframe_gap || !near(k)) continue;
    decision.reference_keyframe = k.keyframe;
    decision.on_mapped_place = true;
    decision.needs_keyframe = false;
    return decision;
  }
  // Elsewhere against the keyframe that shares the most landmarks with the frame (on a first
  // visit, the last keyframe).
  const CovisibleKeyframe& reference = covisible.front();
  decision.reference_keyframe = reference.keyframe;
  decision.needs_keyframe =
      !near(reference) ||
      num_tracked_landmarks < options.keyframe_min_tracked_fraction * reference.held;
  return decision;
}

void Tracker::DecideKeyframe(const std::vector<std::pair<int, int>>& covisible, Frame* frame,
                             const FrameReport& report) const {
  // The keyframes the decision may look at: the most shared one, and those sharing enough to
  // make the frame's place a mapped one.
  std::vector<CovisibleKeyframe> candidates;
  const Rigid3d& rig_from_world = map_.rig_from_world[frame->index];
  for (const auto& [keyframe, shared] : covisible) {
    if (!candidates.empty() && shared < options_.keyframe_min_mapped_landmarks) break;
    const StoredKeyframe& stored = keyframes_.at(keyframe);
    CovisibleKeyframe& k = candidates.emplace_back();
    k.keyframe = keyframe;
    k.shared = shared;
    k.keyframes_since = KeyframesSince(keyframe);
    k.keyframe_from_frame = map_.rig_from_world[keyframe] * rig_from_world.Inverse();
    for (int id : stored.frame.landmark_of[0]) {
      k.held += id >= 0 && map_.landmarks[id].valid ? 1 : 0;
    }
  }
  frame->keyframe_decision =
      internal::DecideKeyframe(candidates, report.num_tracked_landmarks, options_);
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
    landmark.point_in_world = world_from_rig * sp.point_in_cam0;
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

void Tracker::LocalBundleAdjustment(int keyframe, FrameReport* report) {
  if (options_.local_window_frames == 0 || keyframe_order_.size() < 2) return;
  const StageClock timer;
  // The keyframe and those sharing the most landmarks with it: on a first visit the last few
  // keyframes, on a revisit the mapped ones around it, however long ago they were made.
  std::vector<int> window = {keyframe};
  // The saved map's keyframes stay as saved (their observations hold the window's landmarks).
  for (const auto& [other, shared] :
       CovisibleKeyframes(keyframes_.at(keyframe).frame.landmark_of[0])) {
    if (static_cast<int>(window.size()) >= options_.local_window_frames) break;
    if (other != keyframe && !IsSaved(other)) window.push_back(other);
  }
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
  const StageClock load_timer;
  front.frame.index = first_frame_ + index;
  const StereoImages images = load(index);
  load_timer.ChargeTo(&StageTimes::load_s, &front.report);
  front.usable = DetectAndMatchStereo(images, parallel_cameras, &front.frame, &front.report);
  return front;
}

FrameReport Tracker::BackEnd(FrontEndResult front, bool last_frame,
                             const std::function<void(const FrameReport&)>& on_pose) {
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
    if (on_pose) on_pose(report);
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
  if (reference) {
    TrackLocalMap(&frame, &report);
  } else {
    Restart(restart_pose, &frame, &matches, &report);
  }
  map_.has_pose[index] = true;
  ChainTo(reference, matches, &frame);
  frame.keyframe =
      report.state != "tracked" || last_frame || frame.keyframe_decision.needs_keyframe;
  report.keyframe = frame.keyframe;
  const int reference_keyframe = frame.keyframe_decision.reference_keyframe;
  report.reference_keyframe =
      reference_keyframe >= first_frame_ ? reference_keyframe - first_frame_ : -1;
  if (on_pose) {
    // The pose as tracked: a keyframe's mapping below (its landmarks, place recognition, the
    // local adjustment) refines it, and the next frame waits for that, not the caller.
    FrameReport tracked = report;
    tracked.in_map = report.linked && InSavedMap(frame);
    tracked.world_from_rig = map_.rig_from_world[index].Inverse();
    on_pose(tracked);
  }
  if (frame.keyframe) {
    AddKeyframe(&frame, &report);
  } else {
    keyframe_of_frame_[index] = reference_keyframe;
    rig_from_keyframe_[index] =
        map_.rig_from_world[index] * map_.rig_from_world[reference_keyframe].Inverse();
  }
  report.in_map = report.linked && InSavedMap(frame);
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
  // The path of this run (a saved map's keyframes keep the path of theirs).
  if (!keyframe_order_.empty() && !IsSaved(keyframe_order_.back())) {
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
  if (frame->bow) {
    stored.bow = std::move(*frame->bow);
    stored.words = std::move(frame->words);
    frame->bow.reset();
  } else {
    stored.bow = vocabulary_.Transform(frame->features[0].descriptors, &stored.words);
  }
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
  if (!adjusted_globally && !new_segment) LocalBundleAdjustment(index, report);
}

void Tracker::PlaceNonKeyframes() {
  for (size_t f = 0; f < keyframe_of_frame_.size(); ++f) {
    const int keyframe = keyframe_of_frame_[f];
    if (keyframe < 0 || !map_.has_pose[f]) continue;
    map_.rig_from_world[f] = rig_from_keyframe_[f] * map_.rig_from_world[keyframe];
  }
}

namespace {

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

}  // namespace

std::vector<std::optional<Rigid3d>> Tracker::CurrentWorldFromRig() const {
  std::vector<std::optional<Rigid3d>> poses(map_.has_pose.size() - first_frame_);
  for (size_t i = 0; i < poses.size(); ++i) {
    const size_t f = first_frame_ + i;
    if (!map_.has_pose[f]) continue;
    const int keyframe = keyframe_of_frame_[f];
    const Rigid3d rig_from_world = keyframe < 0
                                       ? map_.rig_from_world[f]
                                       : rig_from_keyframe_[f] * map_.rig_from_world[keyframe];
    poses[i] = rig_from_world.Inverse();
  }
  return poses;
}

std::vector<MapPoint> Tracker::CurrentMap() const {
  return ExportMap(map_, options_.min_map_point_frames);
}

void Tracker::Finish(const ProgressSink& progress, SlamResult* result) {
  GlobalBundleAdjustment(rig_, options_, FreeKeyframes(/*linked_only=*/false), progress, &map_,
                         result);
  PlaceNonKeyframes();
  result->num_keyframes = static_cast<int>(keyframe_order_.size());
  for (size_t i = 0; i < result->frames.size(); ++i) {
    FrameReport& frame = result->frames[i];
    const int f = first_frame_ + static_cast<int>(i);
    frame.linked = linked_[f] != 0;
    frame.in_map = frame.in_map && frame.linked;
    result->num_frames_in_map += frame.in_map ? 1 : 0;
    if (!map_.has_pose[f]) {
      ++result->num_lost;
      continue;
    }
    ++result->num_tracked;
    frame.world_from_rig = map_.rig_from_world[f].Inverse();
  }
  result->loops = loops_;
  for (LoopReport& loop : result->loops) {
    loop.frame_index -= first_frame_;
    loop.frame = result->frames[loop.frame_index].name;
    if (IsSaved(loop.matched_frame_index)) {
      loop.matched_frame = saved_names_[loop.matched_frame_index];
      loop.matched_frame_index = -1;
    } else {
      loop.matched_frame_index -= first_frame_;
      loop.matched_frame = result->frames[loop.matched_frame_index].name;
    }
  }
  result->map = ExportMap(map_, options_.min_map_point_frames);
  result->saved_map = ExportSavedMap(result->frames);
}

}  // namespace omnirig::slam::internal
