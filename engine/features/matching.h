#pragma once
// Feature matching for SLAM: between the two cameras of one stereo frame, constrained by the
// calibrated rig's epipolar geometry (paper section 4.1 and Fig. 14: candidates lie on the
// epipolar curve), then triangulated; and between two frames by descriptors alone (ratio test
// and mutual check), for the essential matrix and tracking.

#include <utility>
#include <vector>

#include <Eigen/Core>

#include "engine/features/features.h"
#include "engine/geometry/camera_model.h"

namespace omnirig {

struct StereoMatchOptions {
  // Largest angle between a cam0 bearing and the epipolar plane of its cam1 partner.
  double max_epipolar_error_rad = 3e-3;
  // Lowe's ratio between the best and second-best descriptor distance among the candidates.
  double max_descriptor_ratio = 0.8;
  // Largest L2 distance between matched descriptors (OpenCV's SIFT scale, descriptors of norm
  // ~512): a lone candidate on the curve passes any ratio test, not this.
  double max_descriptor_distance = 250.0;
  double min_parallax_rad = 0.004;  // ~0.25 degrees: 100 mm baseline seen from ~25 m
  double max_range_m = 30.0;
  void Check() const;
};

// A 3D point from one stereo pair: feature0 of cam0 and feature1 of cam1.
struct StereoPoint {
  int feature0 = -1;
  int feature1 = -1;
  Eigen::Vector3d point_in_rig = Eigen::Vector3d::Zero();  // rig frame = cam0 frame, metres
  double range_std_m = 0.0;  // first-order std of the range for ~0.5 px bearing noise
};

// Matches cam0 and cam1 features lying on each other's epipolar curves (mutual best among the
// curve's candidates, ratio test), and triangulates them (midpoint, parallax check).
std::vector<StereoPoint> MatchStereo(const StereoRig& rig, const CameraFeatures& features0,
                                     const CameraFeatures& features1,
                                     const StereoMatchOptions& options);

// Mutual nearest neighbours in descriptor space (L2) that pass the ratio test in both
// directions and lie under max_distance. Returns (row of descriptors_a, row of descriptors_b).
std::vector<std::pair<int, int>> MatchDescriptors(const cv::Mat& descriptors_a,
                                                  const cv::Mat& descriptors_b,
                                                  double max_ratio, double max_distance);

// MatchDescriptors restricted to pairs whose bearings agree with a motion prior: feature i of
// `a` and j of `b` are candidates when the angle between b_from_a_rotation * bearing_a[i] and
// bearing_b[j] is under max_angle_rad (the parallax of a step plus the prior's error). The
// ratio test compares candidates only. Far cheaper than the exhaustive search and rejects
// repeated texture elsewhere on the sphere.
std::vector<std::pair<int, int>> MatchDescriptorsGated(const CameraFeatures& a,
                                                       const CameraFeatures& b,
                                                       const Eigen::Matrix3d& b_from_a_rotation,
                                                       double max_angle_rad, double max_ratio,
                                                       double max_distance);

// MatchDescriptors restricted to pairs in the same group (group_a[i] == group_b[j], e.g. the
// vocabulary node of each descriptor): the ratio test compares a group's members only. Costs
// the exhaustive search divided by about the number of groups.
std::vector<std::pair<int, int>> MatchDescriptorsInGroups(const cv::Mat& descriptors_a,
                                                          const std::vector<int>& group_a,
                                                          const cv::Mat& descriptors_b,
                                                          const std::vector<int>& group_b,
                                                          double max_ratio, double max_distance);

}  // namespace omnirig
