#pragma once
// Epipolar geometry of two central cameras on the unit sphere (paper section 4.1, eqs. 10-17).
//
// Convention: cam2_from_cam1 = (R, t) maps points in camera 1's frame into camera 2's,
//   point_in_cam2 = R * point_in_cam1 + t,
// and the essential matrix is E = [t]_x R, so that for bearings b1 (cam1) and b2 (cam2) of
// one 3D point, b2^T E b1 = 0 (eq. 11). The paper writes E = R S with S = [t']_x and t' the
// translation expressed in camera 1 (eq. 12); R [t']_x = [R t']_x R, so both are the same
// matrix with t = R t'.
//
// Bearings are unit vectors from Lift() (engine/geometry/unified_camera.h); they cover the
// whole sphere, so nothing here assumes points lie "in front" (z > 0) of a camera.
//
// For a calibrated StereoRig (engine/geometry/camera_model.h), camera 1 is cam0 and camera 2
// is cam1: cam2_from_cam1 = rig.cam0_from_cam1.Inverse().

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "engine/geometry/rigid3.h"

namespace omnirig {

// Eq. (16) made an angle: the angle in radians between b2 and the epipolar plane of b1 in
// camera 2, whose normal is N2 = E b1; asin(|b2 . N2| / (|b2| |N2|)). Zero when b1 lies on the
// baseline (N2 = 0: every b2 is consistent). In [0, pi/2].
double EpipolarAngularError(const Eigen::Matrix3d& E, const Eigen::Vector3d& b1,
                            const Eigen::Vector3d& b2);

// The essential matrix of a pose, E = [t]_x R (see the convention above).
Eigen::Matrix3d EssentialFromPose(const Rigid3d& cam2_from_cam1);

// Eqs. (13)-(14) with Hartley-style conditioning, then the constraint enforcement of eq. (15)
// (singular values (s, s, 0), returned with s = 1 and unit Frobenius norm / sqrt(2)).
// Conditioning (the analogue of Hartley's normalisation of image points): each camera's
// bearings are mapped by a linear T that makes their second-moment matrix isotropic, the
// system is solved for the conditioned bearings, and E = T2^T E' T1 before eq. (15). Needs at least
// 8 pairs; throws InvalidArgument on a size mismatch or fewer than 8 pairs. `indices` selects a
// subset (empty means all).
Eigen::Matrix3d EssentialEightPoint(const std::vector<Eigen::Vector3d>& bearings1,
                                    const std::vector<Eigen::Vector3d>& bearings2,
                                    const std::vector<int>& indices = {});

// The four (R, t) of eq. (17) for an essential matrix; t has unit norm.
std::vector<Rigid3d> DecomposeEssential(const Eigen::Matrix3d& E);

// Chooses among the four decompositions by triangulating the given pairs and reprojecting on
// both spheres: a pair supports a candidate when its midpoint triangulation reprojects within
// `max_angular_error_rad` of both bearings (so rays pointing away from the point, the sphere's
// version of "behind the camera", fail). Returns the index of the best candidate and writes the
// number of supporting pairs; -1 when no candidate is supported by any pair.
int SelectDecomposition(const std::vector<Rigid3d>& candidates,
                        const std::vector<Eigen::Vector3d>& bearings1,
                        const std::vector<Eigen::Vector3d>& bearings2,
                        const std::vector<int>& indices, double max_angular_error_rad,
                        int* num_supporting);

struct EssentialRansacOptions {
  // Inlier threshold on EpipolarAngularError. 1e-3 rad is about 0.3 px for a camera whose
  // generalised focal length is ~300 px; scale it with the lens (about 1.5 px / gamma).
  double max_angular_error_rad = 1e-3;
  int max_iterations = 10000;
  double confidence = 0.999;
  uint64_t seed = 0;
  // Fewer inliers than this is reported as a failure.
  int min_inliers = 15;
  // Non-linear refinement of (R, t) on the inliers (Ceres, robust loss) after RANSAC.
  bool refine = true;
  void Check() const;
};

struct EssentialReport {
  bool success = false;
  std::string reason;  // why success is false (empty on success)
  Eigen::Matrix3d E = Eigen::Matrix3d::Zero();
  Rigid3d cam2_from_cam1;         // translation has unit norm: scale is not observable
  std::vector<char> inlier_mask;  // one per pair
  int num_inliers = 0;
  int num_iterations = 0;
  double rms_angular_error_rad = 0.0;  // over inliers, after refinement
  // Median angle between the two rays over the inliers that triangulate in front of both
  // cameras (unit baseline). Near zero for a (nearly) pure rotation, where every translation
  // fits the data and cam2_from_cam1.translation means nothing: callers that need a baseline
  // (SLAM initialisation) should require a few degrees.
  double median_parallax_rad = 0.0;
};

// RANSAC over eight-point samples with the angular error of eq. (16), decomposition (eq. 17)
// chosen by triangulation, then refinement on the inliers. bearings1[i] (unit, cam1 frame) and
// bearings2[i] (unit, cam2 frame) observe the same point. Deterministic for a given seed.
// Throws InvalidArgument on a size mismatch or invalid options; too few pairs or no model are
// reported (success = false, reason set).
EssentialReport EstimateEssentialRansac(const std::vector<Eigen::Vector3d>& bearings1,
                                        const std::vector<Eigen::Vector3d>& bearings2,
                                        const EssentialRansacOptions& options);

// Minimises the sum of squared angular epipolar errors of the given pairs over the rotation and
// the unit translation of `cam2_from_cam1` (Ceres, Cauchy loss of scale `loss_scale_rad`).
// Returns false (leaving the pose untouched) when the solver fails.
bool RefineRelativePose(const std::vector<Eigen::Vector3d>& bearings1,
                        const std::vector<Eigen::Vector3d>& bearings2,
                        const std::vector<int>& indices, double loss_scale_rad,
                        Rigid3d* cam2_from_cam1);

}  // namespace omnirig
