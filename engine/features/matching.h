#pragma once
// Feature matching: between the two cameras of one stereo pair, constrained by the calibrated
// rig's epipolar geometry (paper section 4.1 and Fig. 14: candidates lie on the epipolar
// curve), then triangulated (the sparse one-pair reconstruction and SLAM); and between two
// frames by descriptors alone (ratio test and mutual check), for the essential matrix and
// tracking.

#include <array>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "engine/estimators/triangulation.h"
#include "engine/features/features.h"
#include "engine/geometry/camera_model.h"

namespace omnirig {

// How cam0 and cam1 features are paired on each other's epipolar curves (paper section 4.1,
// Fig. 14). The sparse one-pair reconstruction and SLAM differ in the epipolar test and in
// whether a match must be each feature's best both ways.
struct EpipolarMatchOptions {
  // Largest angle between a bearing and the epipolar plane of its partner (eq. 16).
  double max_epipolar_error_rad = 3e-3;
  // false: the angle is cam1's bearing's from the plane of cam0's, and the pair must lie on the
  // curve's near half (cam1's ray, seen from cam0, turns towards cam0's bearing from the
  // baseline). true: the larger of the two cameras' angles, and the rays must meet in front
  // of both cameras.
  bool check_both_cameras = false;
  // Lowe's ratio between the best and second-best descriptor distance among the candidates.
  double max_descriptor_ratio = 0.8;
  // Largest L2 distance between matched descriptors (OpenCV's SIFT scale, descriptors of norm
  // ~512): a lone candidate on the curve passes any ratio test, not this. Infinity: no bound.
  double max_descriptor_distance = std::numeric_limits<double>::infinity();
  // Keep a match only when it is each feature's best (cam0 -> cam1 and cam1 -> cam0).
  bool mutual_check = true;
  void Check() const;
};

// How the matches are triangulated and which points are kept.
struct StereoTriangulationOptions {
  // The midpoint of the rays, or the optimal angular triangulation (estimators/triangulation.h).
  bool optimal_angular = false;
  TriangulationOptions triangulation;  // parallax and angular-error limits, bearing noise
  double max_range_m = std::numeric_limits<double>::infinity();
  // Points whose range std exceeds this fraction of their range are dropped.
  double max_relative_range_std = std::numeric_limits<double>::infinity();
  void Check() const;
};

// A 3D point from one stereo pair: feature0 of cam0 matched with feature1 of cam1.
struct StereoPoint {
  int feature0 = -1;
  int feature1 = -1;
  Eigen::Vector3d point_in_cam0 = Eigen::Vector3d::Zero();  // metres; the rig's frame is cam0's
  double range_std_m = 0.0;  // first-order, for the triangulation's bearing noise
  double parallax_rad = 0.0;
  double epipolar_error_rad = 0.0;  // as EpipolarMatchOptions::check_both_cameras measures it
  Eigen::Vector2d pixel0 = Eigen::Vector2d::Zero();  // of feature0
  std::array<std::uint8_t, 3> rgb{0, 0, 0};          // of feature0
};

struct StereoMatchReport {
  int num_candidates = 0;  // feature pairs that satisfy the epipolar test
  int num_matches = 0;     // after the ratio test and the mutual check
  int num_rejected_parallax = 0;
  int num_rejected_reprojection = 0;  // includes rays meeting behind a camera
  int num_rejected_range = 0;         // beyond max_range_m or too uncertain
  std::vector<StereoPoint> points;    // in cam0's feature order
};

// Matches cam0 and cam1 features lying on each other's epipolar curves (descriptor distance,
// ratio test among each feature's candidates, mutual check) and triangulates them. The
// features' arrays must all have one entry per feature.
StereoMatchReport MatchStereo(const Rigid3d& cam0_from_cam1, const CameraFeatures& features0,
                              const CameraFeatures& features1, const EpipolarMatchOptions& matching,
                              const StereoTriangulationOptions& triangulation);

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
