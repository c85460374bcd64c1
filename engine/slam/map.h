#pragma once
// The state a SLAM run builds: one rig pose per frame and landmarks with their observations
// in both cameras of the rig. Frames are the rig's positions along the sequence; the rig frame
// is cam0's frame (rig_from_cam0 = identity), so cam1_from_rig = cam0_from_cam1^-1.

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "engine/geometry/rigid3.h"

namespace omnirig::slam {

// One image measurement of a landmark: feature `feature` of camera `camera` (0 or 1) in frame
// `frame`, at `pixel`.
struct Observation {
  int frame = -1;
  int camera = 0;
  int feature = -1;
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
};

struct Landmark {
  Eigen::Vector3d point_in_world = Eigen::Vector3d::Zero();
  std::vector<Observation> observations;
  std::array<std::uint8_t, 3> rgb{0, 0, 0};
  bool valid = true;  // false once pruned (too few observations left)
};

struct SlamMap {
  // Per frame; `has_pose[f]` says whether frame f was tracked and rig_from_world[f] holds.
  std::vector<Rigid3d> rig_from_world;
  std::vector<bool> has_pose;
  std::vector<Landmark> landmarks;

  int AddFrame() {
    rig_from_world.emplace_back();
    has_pose.push_back(false);
    return static_cast<int>(rig_from_world.size()) - 1;
  }
};

}  // namespace omnirig::slam
