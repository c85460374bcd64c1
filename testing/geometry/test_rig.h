#pragma once
// For tests that need a rig's shape (image sizes, a calibration to pass along), not a real
// calibration: one tiny ideal rig instead of one per test file.

#include "engine/geometry/camera_model.h"

namespace omnirig {

// Two identical distortion-free cameras of width x height pixels (xi 0.9, focal 0.3 * height
// px, principal point at the image centre), cam1 0.1 m along cam0's z axis.
inline StereoRig TinyTestRig(int width, int height) {
  StereoRig rig;
  for (CameraModel* camera : {&rig.cam0, &rig.cam1}) {
    camera->width = width;
    camera->height = height;
    camera->intrinsics.params = {
        0.9, 0.3 * height, 0.3 * height, width / 2.0, height / 2.0, 0, 0, 0, 0, 0, 0};
  }
  rig.cam0_from_cam1 = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 0.1));
  return rig;
}

}  // namespace omnirig
