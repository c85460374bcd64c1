#include "engine/stereo/stereo_reconstruct.h"

#include <cmath>
#include <utility>

#include <opencv2/features2d.hpp>

#include "engine/features/image.h"
#include "engine/features/sift_bias.h"
#include "engine/geometry/ply.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {

void StereoReconstructOptions::Check() const {
  OMNIRIG_CHECK_NON_NEGATIVE(max_features);
  OMNIRIG_CHECK_IN(ratio_test, '(', 0, 1, ']');
  OMNIRIG_CHECK_IN(max_epipolar_error_rad, '(', 0, 0.5, ')');
  OMNIRIG_CHECK_IN(min_parallax_rad, '[', 0, M_PI, ')');
  OMNIRIG_CHECK_POSITIVE(max_reprojection_error_rad);
  OMNIRIG_CHECK_POSITIVE(keypoint_std_px);
  OMNIRIG_CHECK_POSITIVE(max_relative_range_std);
  OMNIRIG_CHECK_IN(dark_level, '[', 0, 255, ')');
  OMNIRIG_CHECK_IN(mask_margin_px, '[', 0, 200, ']');
}

MirrorMaskOptions StereoReconstructOptions::MaskOptions() const {
  MirrorMaskOptions mask;
  mask.shape = MirrorMaskOptions::Shape::kDarkRegions;
  mask.dark_level = dark_level;
  mask.margin_px = mask_margin_px;
  return mask;
}

EpipolarMatchOptions StereoReconstructOptions::Matching() const {
  EpipolarMatchOptions matching;
  matching.max_epipolar_error_rad = max_epipolar_error_rad;
  matching.check_both_cameras = true;
  matching.max_descriptor_ratio = ratio_test;
  matching.mutual_check = mutual_check;
  return matching;
}

StereoTriangulationOptions StereoReconstructOptions::Triangulation(const StereoRig& rig) const {
  StereoTriangulationOptions triangulation;
  triangulation.optimal_angular = true;
  triangulation.triangulation.min_parallax_rad = min_parallax_rad;
  triangulation.triangulation.max_angular_error_rad = max_reprojection_error_rad;
  // One keypoint std in pixels is about std / gamma radians near the horizon.
  const double gamma = 0.25 * (rig.cam0.intrinsics.gamma_u() + rig.cam0.intrinsics.gamma_v() +
                               rig.cam1.intrinsics.gamma_u() + rig.cam1.intrinsics.gamma_v());
  triangulation.triangulation.bearing_std_rad = keypoint_std_px / gamma;
  triangulation.max_relative_range_std = max_relative_range_std;
  return triangulation;
}

CameraFeatures DetectAndLift(const cv::Mat& image, const cv::Mat& mask, const CameraModel& camera,
                             const StereoReconstructOptions& options) {
  cv::Ptr<cv::SIFT> sift = cv::SIFT::create(options.max_features);
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  sift->detectAndCompute(ToGreyscale8(image), mask, keypoints, descriptors);
  for (cv::KeyPoint& keypoint : keypoints) {
    keypoint.pt.x -= static_cast<float>(kOpenCvSiftUpscaleBiasPx);
    keypoint.pt.y -= static_cast<float>(kOpenCvSiftUpscaleBiasPx);
  }
  return LiftKeypoints(camera, image, keypoints, descriptors);
}

StereoPairReport ReconstructStereoPair(const StereoRig& rig, const cv::Mat& image0,
                                       const cv::Mat& image1,
                                       const StereoReconstructOptions& options,
                                       const ProgressSink& progress) {
  options.Check();
  CheckPairSizes(rig, image0.cols, image0.rows, image1.cols, image1.rows);
  StereoPairReport report;
  progress.Report(0.0, "detect", "cam0");
  const CameraFeatures f0 =
      DetectAndLift(image0, MirrorMask(image0, PrincipalPoint(rig.cam0), options.MaskOptions()),
                    rig.cam0, options);
  progress.ThrowIfCancelled();
  progress.Report(0.4, "detect", "cam1");
  const CameraFeatures f1 =
      DetectAndLift(image1, MirrorMask(image1, PrincipalPoint(rig.cam1), options.MaskOptions()),
                    rig.cam1, options);
  progress.ThrowIfCancelled();
  report.num_keypoints0 = f0.size();
  report.num_keypoints1 = f1.size();

  progress.Report(0.8, "match");
  StereoMatchReport matched =
      MatchStereo(rig.cam0_from_cam1, f0, f1, options.Matching(), options.Triangulation(rig));
  report.num_candidates = matched.num_candidates;
  report.num_matches = matched.num_matches;
  report.num_rejected_parallax = matched.num_rejected_parallax;
  report.num_rejected_reprojection = matched.num_rejected_reprojection;
  report.num_rejected_uncertain = matched.num_rejected_range;
  report.points = std::move(matched.points);
  progress.ThrowIfCancelled();
  progress.Report(1.0, "triangulate");
  return report;
}

PlyCloud SparseCloud(const std::vector<StereoPoint>& points) {
  PlyCloud cloud;
  cloud.comment = "omnirig stereo_reconstruct: points in cam0's frame, metres";
  for (const StereoPoint& p : points) {
    cloud.positions.push_back(p.point_in_cam0.cast<float>());
    cloud.colours.push_back(p.rgb);
  }
  return cloud;
}

}  // namespace omnirig
