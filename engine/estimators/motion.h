#pragma once
// The rig's motion between two frames from feature matches (paper section 4.1): the essential
// matrix on the sphere with RANSAC and the four-solution disambiguation (engine/stereo), then
// the metric scale from the stereo points of both frames (eq. 18) estimated robustly; and a
// 3D-3D RANSAC (rotation and translation from stereo points alone) for when E is degenerate
// (no translation, too few matches).

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "engine/geometry/rigid3.h"

namespace omnirig {

// A stereo point seen at both frames: its position in the previous rig frame and in the
// current one, with range uncertainties.
struct PointPair {
  Eigen::Vector3d point_in_prev = Eigen::Vector3d::Zero();
  Eigen::Vector3d point_in_curr = Eigen::Vector3d::Zero();
  double std_prev_m = 0.0;
  double std_curr_m = 0.0;
};

struct ScaleOptions {
  // A pair supports a translation when |X_k - R X_{k-1} - t| is under this many combined
  // range stds (plus min_tolerance_m).
  double max_error_sigmas = 3.0;
  double min_tolerance_m = 0.01;
  int min_inliers = 6;
  int max_iterations = 300;
  std::uint64_t seed = 0;
  void Check() const;
};

struct ScaleReport {
  bool success = false;
  std::string reason;
  double scale_m = 0.0;  // the length of the translation along E's unit direction
  Eigen::Vector3d translation_m = Eigen::Vector3d::Zero();
  int num_inliers = 0;
  std::vector<char> inlier_mask;
};

// Eq. (18), t = X_k - R X_{k-1}, made robust: with R and the unit direction t_unit of
// curr_from_prev from the essential matrix, each pair votes for a scale s (the projection of
// its t on t_unit); the scale with the most pairs within tolerance of s * t_unit wins, and is
// refined as the inverse-variance weighted mean over its inliers.
ScaleReport EstimateScale(const Eigen::Matrix3d& curr_from_prev_rotation,
                          const Eigen::Vector3d& t_unit, const std::vector<PointPair>& pairs,
                          const ScaleOptions& options);

struct AbsoluteOrientationReport {
  bool success = false;
  std::string reason;
  Rigid3d curr_from_prev;
  int num_inliers = 0;
  std::vector<char> inlier_mask;
};

// RANSAC over 3-point rigid alignments (Kabsch) of the pairs, then a least-squares fit on the
// inliers. Inlier tolerance as in ScaleOptions. Deterministic for a given seed.
AbsoluteOrientationReport EstimateRigidMotion3D(const std::vector<PointPair>& pairs,
                                                const ScaleOptions& options);

// Least-squares rigid transform dst_from_src with dst_i ~ dst_from_src * src_i (Umeyama's
// closed form without scale). Needs at least 3 non-collinear points for a unique rotation;
// with fewer it still returns the best translation-only fit. Throws InvalidArgument when the
// two lists differ in length or are empty.
Rigid3d AlignRigid(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst);

}  // namespace omnirig
