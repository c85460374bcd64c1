#pragma once
// A stereo dataset's images, paired by name: cam0/NAME and cam1/NAME are the two cameras' images
// of one instant (the relative_pose, stereo_reconstruct and slam jobs' image datasets).

#include <optional>
#include <string>
#include <vector>

namespace omnirig {

struct ImagePairNames {
  std::string name;  // NAME
  std::string cam0;  // "cam0/NAME"
  std::string cam1;  // "cam1/NAME"
};

// Pairs a dataset's images by NAME, sorted by NAME. Throws InvalidArgument listing images
// without a partner, and when there are no cam0/ or cam1/ images at all. Other images are
// ignored.
std::vector<ImagePairNames> MatchImagePairs(const std::vector<std::string>& image_names);

// A frame's name from its capture time: "t%010.3f", e.g. "t000012.345" (videos' frames, their
// container time) or "t1700000000.050" (recordings' frames, their header stamp);
// NameAsTimestamp reads it back.
std::string FrameName(double timestamp_s);

// NAME read as a number, as datasets often name frames by their time ("1403636579.763.png"),
// or "t" and a number as recordings do ("t000012.345.png", slam::FrameName); nullopt when it is
// not one.
std::optional<double> NameAsTimestamp(const std::string& name);

}  // namespace omnirig
