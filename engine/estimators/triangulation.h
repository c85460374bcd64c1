#pragma once
// Triangulation of a bearing pair from two central cameras with a known relative pose.
//
// cam2_from_cam1 maps camera 1's frame into camera 2's (point_in_cam2 = R point_in_cam1 + t);
// bearing1 is in camera 1's frame, bearing2 in camera 2's, both unit. The point is returned in
// camera 1's frame, in the unit of the translation (metres for a metric rig, baseline units
// after EstimateEssentialRansac).

#include <string>

#include <Eigen/Core>

#include "engine/geometry/rigid3.h"

namespace omnirig {

struct TriangulationOptions {
  // Rays closer to parallel than this are rejected (depth is unobservable).
  double min_parallax_rad = 1.0 * 3.14159265358979323846 / 180.0;
  // Std of the angular noise of one bearing, for range_std_m.
  double bearing_std_rad = 1e-3;
  // The triangulated point must reproject within this angle of both bearings (rejects rays
  // that meet behind one camera, and, for the midpoint, rays that pass far apart).
  double max_angular_error_rad = 1e-2;
  void Check() const;
};

struct TriangulatedPoint {
  bool valid = false;
  std::string reason;  // why not valid: "parallax", "behind", "reprojection", "degenerate"
  Eigen::Vector3d point_in_cam1 = Eigen::Vector3d::Zero();
  // Angle between the two rays at the point, radians.
  double parallax_rad = 0.0;
  // First-order std of the range from camera 1 given TriangulationOptions::bearing_std_rad on
  // both bearings: sigma * sqrt(r2^2 + r1^2 cos^2(parallax)) / sin(parallax).
  double range_std_m = 0.0;
  // Angles between the point's direction and each bearing, radians.
  double angular_error1_rad = 0.0;
  double angular_error2_rad = 0.0;
};

// The midpoint of the shortest segment between the two rays.
TriangulatedPoint TriangulateMidpoint(const Rigid3d& cam2_from_cam1,
                                      const Eigen::Vector3d& bearing1,
                                      const Eigen::Vector3d& bearing2,
                                      const TriangulationOptions& options = {});

// Optimal two-view triangulation for the L2 angular error (Lee & Civera, "Closed-form optimal
// two-view triangulation based on angular errors", ICCV 2019): the epipolar plane through the
// baseline that minimises sin^2 of both rays' angles to it is found in closed form (a 2x2
// eigenproblem), both bearings are corrected onto it, and the corrected (coplanar) rays are
// intersected exactly.
TriangulatedPoint TriangulateOptimalAngular(const Rigid3d& cam2_from_cam1,
                                            const Eigen::Vector3d& bearing1,
                                            const Eigen::Vector3d& bearing2,
                                            const TriangulationOptions& options = {});

}  // namespace omnirig
