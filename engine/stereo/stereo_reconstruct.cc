#include "engine/stereo/stereo_reconstruct.h"

#include <cmath>
#include <limits>
#include <set>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/calib/detect.h"
#include "engine/estimators/essential.h"
#include "engine/estimators/triangulation.h"
#include "engine/features/descriptor_match.h"
#include "engine/features/image.h"
#include "engine/features/sift_bias.h"
#include "engine/geometry/ply.h"
#include "engine/geometry/unified_camera.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

float SquaredDistance(const float* a, const float* b, int n) {
  float sum = 0.f;
  for (int k = 0; k < n; ++k) {
    const float d = a[k] - b[k];
    sum += d * d;
  }
  return sum;
}

// True when the rays from cam0's centre along d0 and from c1 along d1 (cam0 frame) meet in
// front of both cameras; nearly parallel rays (a point at infinity) count as meeting in front
// when they point the same way.
bool MeetInFront(const Eigen::Vector3d& c1, const Eigen::Vector3d& d0, const Eigen::Vector3d& d1) {
  const double b = d0.dot(d1);
  const double denom = 1.0 - b * b;
  if (denom < 1e-12) return b > 0.0;
  const double e = d0.dot(c1);
  const double f = d1.dot(c1);
  return (e - b * f) / denom > 0.0 && (b * e - f) / denom > 0.0;
}

struct Candidate {
  int i, j;
  float squared_distance;
  double epipolar_error_rad;
};

std::array<uint8_t, 3> ColourAt(const cv::Mat& image, const cv::Point2f& pt) {
  const int x = std::clamp(static_cast<int>(std::lround(pt.x)), 0, image.cols - 1);
  const int y = std::clamp(static_cast<int>(std::lround(pt.y)), 0, image.rows - 1);
  if (image.channels() == 1) {
    const uint8_t g = image.at<uint8_t>(y, x);
    return {g, g, g};
  }
  const cv::Vec3b bgr = image.at<cv::Vec3b>(y, x);
  return {bgr[2], bgr[1], bgr[0]};
}

}  // namespace

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

cv::Mat MirrorMask(const cv::Mat& image, const CameraModel& camera,
                   const StereoReconstructOptions& options) {
  cv::Mat blurred;
  cv::GaussianBlur(ToGreyscale8(image), blurred, cv::Size(5, 5), 0.0);
  cv::Mat dark = blurred <= options.dark_level;
  cv::Mat labels;
  cv::connectedComponents(dark, labels, 8, CV_32S);
  // Labels of the dark regions outside the rim (touching the border) and of the hole (at the
  // principal point); label 0 is the bright background of connectedComponents.
  std::set<int> excluded;
  for (int x = 0; x < labels.cols; ++x) {
    excluded.insert(labels.at<int>(0, x));
    excluded.insert(labels.at<int>(labels.rows - 1, x));
  }
  for (int y = 0; y < labels.rows; ++y) {
    excluded.insert(labels.at<int>(y, 0));
    excluded.insert(labels.at<int>(y, labels.cols - 1));
  }
  const int cx = static_cast<int>(std::lround(camera.intrinsics.u0()));
  const int cy = static_cast<int>(std::lround(camera.intrinsics.v0()));
  if (cx >= 0 && cy >= 0 && cx < labels.cols && cy < labels.rows) {
    excluded.insert(labels.at<int>(cy, cx));
  }
  excluded.erase(0);
  cv::Mat mask(image.size(), CV_8U, cv::Scalar(255));
  for (int y = 0; y < labels.rows; ++y) {
    const int* row = labels.ptr<int>(y);
    uint8_t* out = mask.ptr<uint8_t>(y);
    for (int x = 0; x < labels.cols; ++x) {
      if (excluded.count(row[x])) out[x] = 0;
    }
  }
  if (options.mask_margin_px > 0) {
    const int k = 2 * options.mask_margin_px + 1;
    cv::erode(mask, mask, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(k, k)));
  }
  return mask;
}

LiftedFeatures DetectAndLift(const cv::Mat& image, const cv::Mat& mask, const CameraModel& camera,
                             const StereoReconstructOptions& options) {
  cv::Ptr<cv::SIFT> sift = cv::SIFT::create(options.max_features);
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  sift->detectAndCompute(ToGreyscale8(image), mask, keypoints, descriptors);
  for (cv::KeyPoint& keypoint : keypoints) {
    keypoint.pt.x -= static_cast<float>(kOpenCvSiftUpscaleBiasPx);
    keypoint.pt.y -= static_cast<float>(kOpenCvSiftUpscaleBiasPx);
  }
  LiftedFeatures features;
  std::vector<int> kept_rows;
  for (size_t k = 0; k < keypoints.size(); ++k) {
    const std::optional<Eigen::Vector3d> bearing =
        Lift(camera.intrinsics, Eigen::Vector2d(keypoints[k].pt.x, keypoints[k].pt.y));
    if (!bearing) continue;
    features.keypoints.push_back(keypoints[k]);
    features.bearings.push_back(*bearing);
    kept_rows.push_back(static_cast<int>(k));
  }
  features.descriptors.create(static_cast<int>(kept_rows.size()), descriptors.cols, CV_32F);
  for (size_t r = 0; r < kept_rows.size(); ++r) {
    descriptors.row(kept_rows[r]).copyTo(features.descriptors.row(static_cast<int>(r)));
  }
  return features;
}

std::vector<StereoMatch> MatchAlongEpipolarCurves(const LiftedFeatures& features0,
                                                  const LiftedFeatures& features1,
                                                  const Rigid3d& cam1_from_cam0,
                                                  const StereoReconstructOptions& options,
                                                  int* num_candidates) {
  const int n0 = static_cast<int>(features0.bearings.size());
  const int n1 = static_cast<int>(features1.bearings.size());
  std::vector<StereoMatch> matches;
  if (num_candidates) *num_candidates = 0;
  if (n0 == 0 || n1 == 0) return matches;
  OMNIRIG_CHECK(features0.descriptors.cols == features1.descriptors.cols,
                "descriptor sizes differ between the two images");

  // Unit normals of the epipolar planes: of b0 in cam1 (E b0) and of b1 in cam0 (E^T b1).
  // A bearing along the baseline has no plane (and no depth): it gets a zero normal and no
  // candidates.
  const Eigen::Matrix3d e = EssentialFromPose(cam1_from_cam0);
  const auto unit_or_zero = [](const Eigen::Vector3d& v) -> Eigen::Vector3d {
    const double n = v.norm();
    return n > 1e-9 ? Eigen::Vector3d(v / n) : Eigen::Vector3d::Zero();
  };
  std::vector<Eigen::Vector3d> normals_in1(n0), normals_in0(n1), rays1_in0(n1);
  for (int i = 0; i < n0; ++i) normals_in1[i] = unit_or_zero(e * features0.bearings[i]);
  const Eigen::Quaterniond cam0_from_cam1_rotation = cam1_from_cam0.rotation.conjugate();
  for (int j = 0; j < n1; ++j) {
    normals_in0[j] = unit_or_zero(e.transpose() * features1.bearings[j]);
    rays1_in0[j] = cam0_from_cam1_rotation * features1.bearings[j];
  }
  const Eigen::Vector3d c1_in0 = -(cam0_from_cam1_rotation * cam1_from_cam0.translation);
  const double sin_max = std::sin(options.max_epipolar_error_rad);

  std::vector<Candidate> candidates;
  std::vector<BestTwo> best0(n0), best1(n1);
  const int dims = features0.descriptors.cols;
  for (int i = 0; i < n0; ++i) {
    if (normals_in1[i].isZero()) continue;
    const float* desc0 = features0.descriptors.ptr<float>(i);
    for (int j = 0; j < n1; ++j) {
      const double s1 = std::abs(normals_in1[i].dot(features1.bearings[j]));
      if (s1 > sin_max) continue;
      const double s0 = std::abs(normals_in0[j].dot(features0.bearings[i]));
      if (s0 > sin_max || normals_in0[j].isZero()) continue;
      if (!MeetInFront(c1_in0, features0.bearings[i], rays1_in0[j])) continue;
      const float d = SquaredDistance(desc0, features1.descriptors.ptr<float>(j), dims);
      candidates.push_back({i, j, d, std::asin(std::max(s0, s1))});
      best0[i].Add(j, d);
      best1[j].Add(i, d);
    }
  }
  if (num_candidates) *num_candidates = static_cast<int>(candidates.size());
  for (const Candidate& c : candidates) {
    if (best0[c.i].best != c.j || !best0[c.i].PassesRatio(options.ratio_test)) continue;
    if (options.mutual_check &&
        (best1[c.j].best != c.i || !best1[c.j].PassesRatio(options.ratio_test))) {
      continue;
    }
    matches.push_back({c.i, c.j, c.epipolar_error_rad});
  }
  return matches;
}

namespace {

// Triangulates report->matches (optimal angular method) into report->points, counting the
// rejections.
void TriangulateMatches(const StereoRig& rig, const LiftedFeatures& f0, const LiftedFeatures& f1,
                        const cv::Mat& image0, const StereoReconstructOptions& options,
                        StereoPairReport* report) {
  const Rigid3d cam1_from_cam0 = rig.cam0_from_cam1.Inverse();
  TriangulationOptions triangulation;
  triangulation.min_parallax_rad = options.min_parallax_rad;
  triangulation.max_angular_error_rad = options.max_reprojection_error_rad;
  // One keypoint std in pixels is about std / gamma radians near the horizon.
  const double gamma = 0.25 * (rig.cam0.intrinsics.gamma_u() + rig.cam0.intrinsics.gamma_v() +
                               rig.cam1.intrinsics.gamma_u() + rig.cam1.intrinsics.gamma_v());
  triangulation.bearing_std_rad = options.keypoint_std_px / gamma;
  for (const StereoMatch& match : report->matches) {
    const TriangulatedPoint t = TriangulateOptimalAngular(cam1_from_cam0, f0.bearings[match.index0],
                                                          f1.bearings[match.index1], triangulation);
    if (!t.valid) {
      (t.reason == "parallax" ? report->num_rejected_parallax
                              : report->num_rejected_reprojection)++;
      continue;
    }
    if (t.range_std_m > options.max_relative_range_std * t.point_in_cam1.norm()) {
      ++report->num_rejected_uncertain;
      continue;
    }
    SparsePoint point;
    point.point_in_cam0 = t.point_in_cam1;  // the triangulation's camera 1 is the rig's cam0
    const cv::Point2f& p0 = f0.keypoints[match.index0].pt;
    point.rgb = ColourAt(image0, p0);
    point.pixel0 = Eigen::Vector2d(p0.x, p0.y);
    point.parallax_rad = t.parallax_rad;
    point.range_std_m = t.range_std_m;
    report->points.push_back(point);
  }
}

}  // namespace

StereoPairReport ReconstructStereoPair(const StereoRig& rig, const cv::Mat& image0,
                                       const cv::Mat& image1,
                                       const StereoReconstructOptions& options,
                                       const ProgressSink& progress) {
  options.Check();
  CheckPairSizes(rig, image0.cols, image0.rows, image1.cols, image1.rows);
  StereoPairReport report;
  progress.Report(0.0, "detect", "cam0");
  const LiftedFeatures f0 =
      DetectAndLift(image0, MirrorMask(image0, rig.cam0, options), rig.cam0, options);
  progress.ThrowIfCancelled();
  progress.Report(0.4, "detect", "cam1");
  const LiftedFeatures f1 =
      DetectAndLift(image1, MirrorMask(image1, rig.cam1, options), rig.cam1, options);
  progress.ThrowIfCancelled();
  report.num_keypoints0 = static_cast<int>(f0.keypoints.size());
  report.num_keypoints1 = static_cast<int>(f1.keypoints.size());

  const Rigid3d cam1_from_cam0 = rig.cam0_from_cam1.Inverse();
  progress.Report(0.8, "match");
  report.matches =
      MatchAlongEpipolarCurves(f0, f1, cam1_from_cam0, options, &report.num_candidates);
  report.num_matches = static_cast<int>(report.matches.size());
  progress.ThrowIfCancelled();
  progress.Report(0.95, "triangulate");

  TriangulateMatches(rig, f0, f1, image0, options, &report);
  progress.Report(1.0, "triangulate");
  return report;
}

PlyCloud SparseCloud(const std::vector<SparsePoint>& points) {
  PlyCloud cloud;
  cloud.comment = "omnirig stereo_reconstruct: points in cam0's frame, metres";
  for (const SparsePoint& p : points) {
    cloud.positions.push_back(p.point_in_cam0.cast<float>());
    cloud.colours.push_back(p.rgb);
  }
  return cloud;
}

}  // namespace omnirig
