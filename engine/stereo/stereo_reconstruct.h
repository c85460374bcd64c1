#pragma once
// "Instant 3D" from one stereo pair of a calibrated rig (the paper's section 5: a 3D
// reconstruction without displacement): SIFT features in both images, inside the mirror disk,
// lifted to bearings, matched cam0 <-> cam1 under the rig's known epipolar geometry, and
// triangulated. Reads as mask -> detect and lift -> match -> triangulate, one function each.
//
// Frames: points are returned in cam0's frame, in metres (the rig's baseline unit).

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/features/features.h"
#include "engine/features/matching.h"
#include "engine/features/mirror_mask.h"
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
  // The mirror mask (engine/features/mirror_mask.h, shape kDarkRegions): pixels whose
  // 5x5-blurred grey level is at or below dark_level are outside the mirror (rim, central hole,
  // housing) when they touch the border or the principal point; the mask is then eroded by
  // mask_margin_px so that the disk's edge does not produce features.
  double dark_level = 20.0;
  int mask_margin_px = 6;
  MirrorMaskOptions MaskOptions() const;
  // Matching on the epipolar curves (engine/features/matching.h): the larger of both
  // cameras' epipolar angles, rays meeting in front of both cameras, no descriptor distance
  // bound.
  EpipolarMatchOptions Matching() const;
  // The optimal angular triangulation with the limits above, the keypoint noise turned into a
  // bearing noise with the rig's mean focal length.
  StereoTriangulationOptions Triangulation(const StereoRig& rig) const;

  void Check() const;
};

struct StereoPairReport {
  int num_keypoints0 = 0;  // lifted keypoints inside the mask
  int num_keypoints1 = 0;
  int num_candidates = 0;  // feature pairs that satisfy the epipolar constraint
  int num_matches = 0;     // after ratio test and mutual check
  int num_rejected_parallax = 0;
  int num_rejected_reprojection = 0;  // includes rays meeting behind a camera
  int num_rejected_uncertain = 0;     // range std above max_relative_range_std
  std::vector<StereoPoint> points;    // one per accepted match, in cam0's keypoint order
};

// SIFT (OpenCV) at full resolution inside `mask`, lifted through the camera model
// (LiftKeypoints).
CameraFeatures DetectAndLift(const cv::Mat& image, const cv::Mat& mask, const CameraModel& camera,
                             const StereoReconstructOptions& options);

// The whole pipeline for one pair. Images are 8-bit BGR or grey, of the rig's image sizes
// (throws InvalidArgument otherwise). Calls progress.ThrowIfCancelled() between steps.
StereoPairReport ReconstructStereoPair(const StereoRig& rig, const cv::Mat& image0,
                                       const cv::Mat& image1,
                                       const StereoReconstructOptions& options,
                                       const ProgressSink& progress = ProgressSink());

// The points as a PLY cloud (engine/geometry/ply.h, WritePly): positions in cam0's frame
// (metres) and colours.
PlyCloud SparseCloud(const std::vector<StereoPoint>& points);

}  // namespace omnirig
