#pragma once
// Epipolar curves of a calibrated stereo rig (paper section 5, Fig. 14): the image in one camera
// of the ray through a pixel of the other. On the sphere the ray's directions seen from the
// other camera form an arc of a great circle, from the epipole (the direction of the first
// camera's centre, depth 0) to the ray's vanishing direction (depth infinity); through the
// unified model that arc becomes a curve (a conic for a distortion-free mirror).

#include <vector>

#include <Eigen/Core>

#include "engine/geometry/camera_model.h"

namespace omnirig {

using Polyline2d = std::vector<Eigen::Vector2d>;

// The epipolar curve, in pixels of the OTHER camera, of `pixel` in camera `from_camera` (0 for
// rig.cam0, 1 for rig.cam1). The arc is sampled at `num_samples` angles uniformly spaced from
// the epipole (excluded) to the vanishing direction (included); samples that do not project
// or fall outside the other image are dropped and the curve is split there into several
// polylines (each with at least 2 points). Empty when the pixel does not lift. Throws
// InvalidArgument for from_camera not in {0, 1} or num_samples < 2.
std::vector<Polyline2d> EpipolarCurve(const StereoRig& rig, int from_camera,
                                      const Eigen::Vector2d& pixel, int num_samples = 200);

}  // namespace omnirig
