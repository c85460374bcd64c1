#pragma once
// The closed-form steps of the relative pose (paper section 3.3): eq. (9) with the projection of
// R onto a rotation, the paper-style average of per-pair poses, and the degeneracy measure.

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "engine/geometry/rigid3.h"

namespace omnirig {

// The rotation nearest to `m` in the Frobenius norm: U diag(1, 1, det(U V^T)) V^T from the SVD
// m = U S V^T. A naive renormalisation of rows or columns is not a rotation in general.
Eigen::Matrix3d ProjectToRotation(const Eigen::Matrix3d& m);

// Eq. (9): the 12 unknowns (R row-major, t) of point_in_cam0 = R * point_in_cam1 + t by linear
// least squares over all correspondences (the same board corner expressed in both cameras'
// frames through their board poses), R projected onto SO(3), then t re-solved for that R
// (the mean of point_in_cam0 - R * point_in_cam1). nullopt with fewer than 4 correspondences or
// when the system is rank-deficient (all points coplanar), see SpreadEigenRatio.
std::optional<Rigid3d> SolveRelativePoseLinear(const std::vector<Eigen::Vector3d>& points_in_cam0,
                                               const std::vector<Eigen::Vector3d>& points_in_cam1);

// The paper's alternative, kept for comparison: one cam0_from_cam1 per pair
// (cam0_from_board * cam1_from_board^-1), averaged: the chordal L2 mean of the rotations
// (ProjectToRotation of the summed matrices) and the mean of the translations.
Rigid3d AverageRigidPoses(const std::vector<Rigid3d>& poses);

// Smallest over largest eigenvalue of the points' scatter matrix (about their centroid), in
// [0, 1]: 0 for coplanar points (one board pose), larger the more the points fill space.
double SpreadEigenRatio(const std::vector<Eigen::Vector3d>& points);

}  // namespace omnirig
