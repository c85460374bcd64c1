#include "engine/slam/tracker.h"

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
  report->state = last_ ? "reinitialised" : "initialised";
  report->linked = !last_;
  if (last_) segment_ = Segment{frame->index, static_cast<int>(map_.landmarks.size())};
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
