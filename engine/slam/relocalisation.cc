#include "engine/slam/tracker.h"

#include <map>
#include <set>

#include "engine/util/check.h"

// Relocalisation: a frame that fails against the last frame is localised against the map's
// keyframes; when that fails too, a new segment starts, and its keyframes re-link it to the
// map when they recognise a mapped place.
namespace omnirig::slam::internal {

const Frame* Tracker::Relocalise(Frame* frame, std::vector<std::pair<int, int>>* matches,
                                 FrameReport* report) {
  if (keyframes_.empty()) return nullptr;
  const StageClock timer;
  frame->bow = vocabulary_.Transform(frame->features[0].descriptors, &frame->words);
  const std::vector<KeyframeDatabase::Candidate> candidates = database_.Query(
      *frame->bow, [](int) { return true; }, options_.loop_min_score, options_.loop_max_candidates);
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
  // With a saved map even the first frame is not in the map's world until it recognises a
  // mapped place.
  const bool restart = last_ || first_frame_ > 0;
  report->state = restart ? "reinitialised" : "initialised";
  report->linked = !restart;
  if (restart) segment_ = Segment{frame->index, static_cast<int>(map_.landmarks.size())};
}

void Tracker::LoadMap(const SavedMap& saved) {
  OMNIRIG_CHECK(!saved.keyframes.empty(), "the saved map holds no keyframe");
  for (size_t k = 0; k < saved.keyframes.size(); ++k) {
    const SavedKeyframe& source = saved.keyframes[k];
    const int index = map_.AddFrame();
    map_.rig_from_world[index] = source.rig_from_world;
    map_.has_pose[index] = true;
    keyframe_of_frame_.push_back(-1);
    rig_from_keyframe_.emplace_back();
    linked_.push_back(source.linked ? 1 : 0);
    saved_names_.push_back(source.name);
    StoredKeyframe& stored = keyframes_[index];
    stored.order = index;
    stored.path_m = source.path_m;
    stored.linked = source.linked;
    Frame& frame = stored.frame;
    frame.index = index;
    frame.keyframe = true;
    frame.features[0] = source.cam0;
    frame.stereo = source.stereo;
    frame.stereo_of_feature0.assign(source.cam0.size(), -1);
    for (size_t s = 0; s < source.stereo.size(); ++s) {
      frame.stereo_of_feature0[source.stereo[s].feature0] = static_cast<int>(s);
    }
    frame.landmark_of[0] = source.landmark_of[0];
    frame.landmark_of[1] = source.landmark_of[1];
    // The descriptors were SIFT's integers as floats: the same words as when it was made.
    stored.bow = vocabulary_.Transform(source.cam0.descriptors, &stored.words);
    keyframe_order_.push_back(index);
    database_.Add(index, stored.bow);
  }
  map_.landmarks = saved.landmarks;
  first_frame_ = static_cast<int>(saved.keyframes.size());
  num_saved_landmarks_ = static_cast<int>(saved.landmarks.size());
}

SavedMap Tracker::ExportSavedMap(const std::vector<FrameReport>& frames) const {
  SavedMap saved;
  std::map<int, int> position;  // frame index -> saved keyframe
  for (int index : keyframe_order_) {
    const StoredKeyframe& stored = keyframes_.at(index);
    if (!stored.linked || !map_.has_pose[index]) continue;
    position[index] = static_cast<int>(saved.keyframes.size());
    SavedKeyframe& k = saved.keyframes.emplace_back();
    k.name = IsSaved(index) ? saved_names_[index] : frames.at(index - first_frame_).name;
    k.rig_from_world = map_.rig_from_world[index];
    k.linked = true;
    k.path_m = stored.path_m;
    k.cam0 = stored.frame.features[0];
    k.num_cam1_features = static_cast<int>(stored.frame.landmark_of[1].size());
    k.stereo = stored.frame.stereo;
  }
  // Landmarks seen from two rig positions of kept keyframes or from both cameras of one (a
  // single observation constrains nothing), renumbered.
  std::vector<int> new_id(map_.landmarks.size(), -1);
  for (size_t id = 0; id < map_.landmarks.size(); ++id) {
    const Landmark& landmark = map_.landmarks[id];
    if (!landmark.valid) continue;
    Landmark kept;
    kept.point_in_world = landmark.point_in_world;
    kept.rgb = landmark.rgb;
    for (const Observation& o : landmark.observations) {
      const auto it = position.find(o.frame);
      if (it == position.end()) continue;
      Observation moved = o;
      moved.frame = it->second;
      kept.observations.push_back(moved);
    }
    if (kept.observations.size() < 2) continue;
    new_id[id] = static_cast<int>(saved.landmarks.size());
    saved.landmarks.push_back(std::move(kept));
  }
  for (const auto& [index, k] : position) {
    const Frame& frame = keyframes_.at(index).frame;
    for (int c = 0; c < 2; ++c) {
      std::vector<int>& of = saved.keyframes[k].landmark_of[c];
      for (int id : frame.landmark_of[c]) of.push_back(id >= 0 ? new_id[id] : -1);
    }
  }
  // A feature keeps its landmark only where the landmark keeps its observation.
  std::vector<std::vector<char>> observed[2];
  for (const SavedKeyframe& k : saved.keyframes) {
    for (int c = 0; c < 2; ++c) observed[c].emplace_back(k.landmark_of[c].size(), 0);
  }
  for (const Landmark& landmark : saved.landmarks) {
    for (const Observation& o : landmark.observations) observed[o.camera][o.frame][o.feature] = 1;
  }
  for (size_t k = 0; k < saved.keyframes.size(); ++k) {
    for (int c = 0; c < 2; ++c) {
      std::vector<int>& of = saved.keyframes[k].landmark_of[c];
      for (size_t f = 0; f < of.size(); ++f) {
        if (!observed[c][k][f]) of[f] = -1;
      }
    }
  }
  return saved;
}

std::vector<int> Tracker::FreeKeyframes(bool linked_only) const {
  std::vector<int> free;
  for (int keyframe : keyframe_order_) {
    if (IsSaved(keyframe) || (linked_only && !keyframes_.at(keyframe).linked)) continue;
    free.push_back(keyframe);
  }
  return free;
}

bool Tracker::InSavedMap(const Frame& frame) const {
  if (first_frame_ == 0) return false;
  std::set<int> seen;
  for (const std::vector<int>& of : frame.landmark_of) {
    for (int id : of) {
      if (id >= 0 && id < num_saved_landmarks_ && map_.landmarks[id].valid) seen.insert(id);
    }
  }
  return static_cast<int>(seen.size()) >= options_.min_tracked_landmarks;
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

}  // namespace omnirig::slam::internal
