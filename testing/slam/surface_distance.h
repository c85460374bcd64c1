#pragma once
// Distance from a point to the nearest surface of a synthetic scene (ground truth for the
// accuracy of a SLAM map). Test and benchmark support: links engine/synth.

#include <Eigen/Core>

#include "engine/synth/scene.h"

namespace omnirig::slam {

// Distance in metres from point_in_world to the nearest primitive surface of `scene` (planes,
// boxes, cylinders with caps, checkerboards as planes).
double DistanceToSceneSurface(const synth::Scene& scene, const Eigen::Vector3d& point_in_world);

// Distance in metres along the ray origin + t * unit_direction (t > 1e-6) to the first surface of
// `scene` it meets (planes, boxes, cylinders with caps, checkerboards as planes); infinity when
// it meets none. The true range of a reconstructed point along its line of sight.
double RangeToSceneSurface(const synth::Scene& scene, const Eigen::Vector3d& origin_in_world,
                           const Eigen::Vector3d& unit_direction_in_world);

}  // namespace omnirig::slam
