#pragma once
// A SLAM run's map kept for later runs: the keyframes (pose, cam0's features with their SIFT
// descriptors, stereo points, which landmark each feature sees) and the landmarks with their
// observations. A later run loads it before its first frame (SlamOptions' saved map, slam.h):
// its frames are localised in this map's world against these keyframes (place recognition,
// then P3P) and tracked on these landmarks, and what it maps where this map has nothing joins
// it. Only keyframes in the map's world are kept (a re-initialised segment that never recognised
// a mapped place is left out), numbered 0.. in the order they were made; observations refer to
// keyframes by that number.
//
// File format (slam_map.bin), little-endian:
//   "OMNIRIG-MAP\n" (12 bytes), uint32 version (kSavedMapVersion), uint32 num_keyframes,
//   uint32 num_landmarks, then per keyframe:
//     uint32 name length, name bytes; rig_from_world as 7 float64 (qw qx qy qz tx ty tz);
//     uint8 linked; float64 path_m; uint32 num_cam0_features, per feature float64 pixel x y,
//     float64 bearing x y z, uint8 r g b, 128 uint8 SIFT descriptor; int32 landmark per cam0
//     feature (-1: none); uint32 num_cam1_features, int32 landmark per cam1 feature; uint32
//     num_stereo_points, per point int32 feature0 feature1, float64 point_in_cam0 x y z,
//     range_std_m, parallax_rad, epipolar_error_rad;
//   per landmark: float64 point_in_world x y z, uint8 r g b, uint32 num_observations, per
//     observation int32 keyframe, uint8 camera, int32 feature, float64 pixel x y;
//   "END\n".
// Readers refuse other magic, another version, a truncated file and indices out of range.

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "engine/features/features.h"
#include "engine/features/matching.h"
#include "engine/geometry/rigid3.h"
#include "engine/slam/map.h"

namespace omnirig::slam {

inline constexpr std::uint32_t kSavedMapVersion = 1;

struct SavedKeyframe {
  std::string name;  // the frame's name in the run that made it
  Rigid3d rig_from_world;
  bool linked = true;
  double path_m = 0.0;  // path travelled from the first keyframe, along the keyframes
  CameraFeatures cam0;  // descriptors CV_8U (SIFT's components are integers)
  int num_cam1_features = 0;
  std::vector<int> landmark_of[2];  // per feature of cam0, cam1; -1: none
  std::vector<StereoPoint> stereo;
};

struct SavedMap {
  std::vector<SavedKeyframe> keyframes;
  std::vector<Landmark> landmarks;  // Observation::frame: a keyframe's position above
};

// Throws std::runtime_error when the file cannot be written.
void WriteSavedMap(const std::filesystem::path& path, const SavedMap& map);
// The same bytes WriteSavedMap writes.
std::vector<std::uint8_t> SerializeSavedMap(const SavedMap& map);
// Throws InvalidArgument (naming the file) when it cannot be read, is not a saved map, holds
// another version than kSavedMapVersion, is truncated or inconsistent.
SavedMap ReadSavedMap(const std::filesystem::path& path);
SavedMap DeserializeSavedMap(const std::uint8_t* data, std::size_t size);

}  // namespace omnirig::slam
