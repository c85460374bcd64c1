#pragma once
// Stereo frames from a folder of image pairs (cam0/NAME and cam1/NAME, engine/util/image_pairs.h),
// for RunSlam's StereoFrameLoader; the images are decoded one frame at a time, as SLAM asks.

#include <filesystem>
#include <vector>

#include "engine/slam/slam.h"
#include "engine/util/image_pairs.h"

namespace omnirig::slam {

// Load(k) reads `dir / pairs[k].cam0` and `.cam1` (8-bit BGR) side by side (ReadBoth). Throws
// InvalidArgument naming an image that cannot be read.
StereoFrameLoader StereoImageLoader(std::filesystem::path dir, std::vector<ImagePairNames> pairs);

}  // namespace omnirig::slam
