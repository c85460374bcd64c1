#include "engine/slam/tracker.h"

#include <algorithm>
#include <map>
#include <set>

#include "engine/util/check.h"

// Loop closure: a keyframe's place candidates verified on the sphere, the loop's correction
// spread by the pose graph, the landmarks seen again fused.
namespace omnirig::slam::internal {
namespace {

// Verification matches descriptors within the same node of this level of the vocabulary tree
// (100 nodes of the shipped 10^3-word tree): the exhaustive search cost ~0.07 s CPU per
// candidate on 1024x768 keyframes.
constexpr int kVerificationMatchLevel = 2;

std::vector<int> MatchGroups(const Vocabulary& vocabulary, const std::vector<int>& words) {
  const int level = std::min(kVerificationMatchLevel, vocabulary.depth());
  std::vector<int> groups;
  groups.reserve(words.size());
  for (int word : words) groups.push_back(vocabulary.NodeOf(word, level));
  return groups;
}

}  // namespace

std::optional<PlaceMatch> Tracker::VerifyPlace(const Frame& frame, int keyframe) {
  const StoredKeyframe& stored = keyframes_.at(keyframe);
  const Frame& candidate = stored.frame;
  const std::vector<std::pair<int, int>> matches = MatchDescriptorsInGroups(
      FloatDescriptors(candidate.features[0].descriptors), MatchGroups(vocabulary_, stored.words),
      frame.features[0].descriptors, MatchGroups(vocabulary_, keyframes_.at(frame.index).words),
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
    if (!stored.linked) return false;
    // A saved map's keyframe is of an earlier passage; the drift is this run's since its start.
    const bool saved = IsSaved(keyframe);
    if (!saved && stored.order + options_.loop_min_keyframe_gap >= current.order) return false;
    const double reach =
        options_.loop_max_distance_m +
        options_.loop_max_drift_fraction * (current.path_m - (saved ? 0.0 : stored.path_m));
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
  // The gauge: the first keyframe, or the saved map's keyframes, which stay as saved.
  std::set<int> fixed = {poses.begin()->first};
  for (int f = 0; f < first_frame_; ++f) {
    if (poses.count(f)) fixed.insert(f);
  }
  OptimisePoseGraph(edges, fixed, options_.num_threads, &poses);
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
  BundleAdjustmentOptions global = options_.bundle_adjustment;
  global.num_threads = options_.num_threads;
  BundleAdjust(rig_, FreeKeyframes(/*linked_only=*/true), global, &map_, cancellation_);
  PlaceNonKeyframes();
}

}  // namespace omnirig::slam::internal
