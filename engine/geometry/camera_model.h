#pragma once
// A calibrated camera (intrinsics + image size) and a calibrated stereo rig.

#include "engine/geometry/rigid3.h"
#include "engine/geometry/unified_camera.h"
#include "engine/util/check.h"

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

// Throws InvalidArgument unless a pair's images (width x height each) have the rig's calibrated
// sizes: a rig calibrated at another resolution would place every pixel wrongly.
inline void CheckPairSizes(const StereoRig& rig, int width0, int height0, int width1,
                           int height1) {
  OMNIRIG_CHECK(width0 == rig.cam0.width && height0 == rig.cam0.height,
                "cam0 image is " << width0 << "x" << height0 << " but the rig's cam0 is "
                                 << rig.cam0.width << "x" << rig.cam0.height);
  OMNIRIG_CHECK(width1 == rig.cam1.width && height1 == rig.cam1.height,
                "cam1 image is " << width1 << "x" << height1 << " but the rig's cam1 is "
                                 << rig.cam1.width << "x" << rig.cam1.height);
}

}  // namespace omnirig
