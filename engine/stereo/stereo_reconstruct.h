#pragma once
// "Instant 3D" from one stereo pair of a calibrated rig (the paper's section 5: a 3D
// reconstruction without displacement): SIFT features in both images, inside the mirror disk,
// lifted to bearings, matched cam0 <-> cam1 under the rig's known epipolar geometry, and
// triangulated. Reads as mask -> detect and lift -> match -> triangulate, one function each.
//
// Frames: points are returned in cam0's frame, in metres (the rig's baseline unit).

#include <array>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/geometry/camera_model.h"
#include "engine/geometry/ply.h"
#include "engine/util/progress.h"

namespace omnirig {

struct StereoReconstructOptions {
  // SIFT keypoints kept per image (strongest first); 0 keeps all.
  int max_features = 4000;
  // Lowe's ratio: best descriptor distance < ratio * second best among epipolar candidates.
  double ratio_test = 0.8;
  // A candidate must lie within this angle of the epipolar plane in both cameras (eq. 16).
  double max_epipolar_error_rad = 2e-3;
  // Keep a match only when it is each feature's best (cam0 -> cam1 and cam1 -> cam0).
  bool mutual_check = true;
  // Triangulation: minimum angle between the rays, and maximum angle between the point and
  // each bearing.
  double min_parallax_rad = 1.0 * 3.14159265358979323846 / 180.0;
  double max_reprojection_error_rad = 2e-3;
  // Keypoint position noise, for the per-point range uncertainty (converted to an angle with
  // the cameras' mean focal length). 0.3 px is typical of SIFT's sub-pixel localisation; on the
  // synthetic room (stereo_reconstruct_synth_test) 98% of ranges fall within 3 sigma.
  double keypoint_std_px = 0.3;
  // Points whose range std exceeds this fraction of their range are dropped (far points seen
  // with little parallax).
  double max_relative_range_std = 0.1;
  // Mirror-disk mask: pixels whose 5x5-blurred grey level is at or below dark_level are outside
  // the mirror (rim, central hole, housing); the mask is then eroded by mask_margin_px so that
  // the disk's edge does not produce features.
  double dark_level = 20.0;
  int mask_margin_px = 6;

  void Check() const;
};

// Keypoints of one image with their lifted unit bearings (keypoints that do not lift are
// dropped); descriptors row i belongs to keypoints[i].
struct LiftedFeatures {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;  // CV_32F, one row per keypoint
  std::vector<Eigen::Vector3d> bearings;
};

struct StereoMatch {
  int index0 = -1;  // into cam0's LiftedFeatures
  int index1 = -1;  // into cam1's
  double epipolar_error_rad = 0.0;  // the larger of the two cameras' eq. (16) angles
};

struct SparsePoint {
  Eigen::Vector3d point_in_cam0 = Eigen::Vector3d::Zero();
  std::array<uint8_t, 3> rgb{0, 0, 0};  // colour at the cam0 keypoint
  Eigen::Vector2d pixel0 = Eigen::Vector2d::Zero();
  double parallax_rad = 0.0;
  double range_std_m = 0.0;
};

struct StereoPairReport {
  int num_keypoints0 = 0;  // lifted keypoints inside the mask
  int num_keypoints1 = 0;
  int num_candidates = 0;  // feature pairs that satisfy the epipolar constraint
  int num_matches = 0;     // after ratio test and mutual check
  int num_rejected_parallax = 0;
  int num_rejected_reprojection = 0;  // includes rays meeting behind a camera
  int num_rejected_uncertain = 0;     // range std above max_relative_range_std
  std::vector<StereoMatch> matches;
  std::vector<SparsePoint> points;  // one per accepted match
};

// The mirror disk of an omnidirectional image (CV_8U, 255 inside). Dark regions (see the
// options) that touch the image border (outside the rim) or contain the principal point (the
// central hole) are masked out; dark patches of the scene inside the mirror are kept.
cv::Mat MirrorMask(const cv::Mat& image, const CameraModel& camera,
                   const StereoReconstructOptions& options);

// SIFT (OpenCV) inside `mask`, lifted through the camera model.
LiftedFeatures DetectAndLift(const cv::Mat& image, const cv::Mat& mask, const CameraModel& camera,
                             const StereoReconstructOptions& options);

// Descriptor matching restricted to each feature's epipolar curve: a pair (i, j) is a candidate
// when its bearings lie within max_epipolar_error_rad of each other's epipolar planes and the
// rays meet in front of both cameras (on the epipolar arc, not its antipodal half). Then Lowe's
// ratio test among each feature's candidates and the mutual check. cam1_from_cam0 maps cam0's
// frame into cam1's. Writes the number of candidates when num_candidates is not null.
std::vector<StereoMatch> MatchAlongEpipolarCurves(const LiftedFeatures& features0,
                                                  const LiftedFeatures& features1,
                                                  const Rigid3d& cam1_from_cam0,
                                                  const StereoReconstructOptions& options,
                                                  int* num_candidates = nullptr);

// The whole pipeline for one pair. Images are 8-bit BGR or grey, of the rig's image sizes
// (throws InvalidArgument otherwise). Calls progress.ThrowIfCancelled() between steps.
StereoPairReport ReconstructStereoPair(const StereoRig& rig, const cv::Mat& image0,
                                       const cv::Mat& image1,
                                       const StereoReconstructOptions& options,
                                       const ProgressSink& progress = ProgressSink());

// The points as a PLY cloud (engine/geometry/ply.h, WritePly): positions in cam0's frame
// (metres) and colours.
PlyCloud SparseCloud(const std::vector<SparsePoint>& points);

}  // namespace omnirig
