#pragma once
// The rig's absolute pose from bearings of known world points (relocalisation and re-linking):
// OpenGV's central P3P (Kneip, Scaramuzza and Siegwart 2011) inside OpenGV's RANSAC, on cam0's
// bearings (the rig frame is cam0's), then a least-squares fit on the inliers (OpenGV's
// nonlinear optimisation). OpenGV seeds its RANSAC from the clock or with a constant; the
// problem here re-seeds it from the options so that a run repeats exactly.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "engine/geometry/rigid3.h"

namespace omnirig {

struct AbsolutePoseOptions {
  double max_angular_error_rad = 3e-3;  // inlier threshold on the angle between bearings
  int max_iterations = 500;
  int min_inliers = 15;
  std::uint64_t seed = 0;
  void Check() const;
};

struct AbsolutePoseReport {
  bool success = false;
  std::string reason;  // why not
  Rigid3d rig_from_world;
  int num_inliers = 0;
  std::vector<char> inlier_mask;
};

// `bearings_in_rig[i]` (unit) sees `points_in_world[i]`.
AbsolutePoseReport EstimateAbsolutePose(const std::vector<Eigen::Vector3d>& bearings_in_rig,
                                        const std::vector<Eigen::Vector3d>& points_in_world,
                                        const AbsolutePoseOptions& options);

}  // namespace omnirig
