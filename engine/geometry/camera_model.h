#pragma once
// A calibrated camera (intrinsics + image size) and a calibrated stereo rig.

#include "engine/geometry/rigid3.h"
#include "engine/geometry/unified_camera.h"

namespace omnirig {

struct CameraModel {
  UnifiedIntrinsics intrinsics;
  int width = 0;   // image size in pixels
  int height = 0;
};

// Two cameras and the metric pose between them. cam0_from_cam1 maps points in cam1's frame into
// cam0's (the paper's eq. 8: the pose of the second sensor with respect to the first).
struct StereoRig {
  CameraModel cam0;
  CameraModel cam1;
  Rigid3d cam0_from_cam1;
};

}  // namespace omnirig
