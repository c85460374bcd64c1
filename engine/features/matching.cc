#include "engine/features/matching.h"

#include <cmath>
#include <limits>
#include <unordered_map>

#include <opencv2/core/hal/hal.hpp>
#include <opencv2/features2d.hpp>

#include "engine/estimators/epipolar.h"
#include "engine/estimators/essential.h"
#include "engine/estimators/triangulation.h"
#include "engine/features/descriptor_match.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

// Distances are squared: the bound is squared too.
bool Passes(const BestTwo& best, double ratio, double max_distance) {
  return best.best >= 0 && best.d1 <= max_distance * max_distance && best.PassesRatio(ratio);
}

// OpenCV's vectorised kernel: the compiler may not reorder a float sum into SIMD lanes.
float SquaredDistance(const float* a, const float* b, int n) {
  return cv::hal::normL2Sqr_(a, b, n);
}

}  // namespace

void StereoMatchOptions::Check() const {
  OMNIRIG_CHECK_POSITIVE(max_epipolar_error_rad);
  OMNIRIG_CHECK_IN(max_descriptor_ratio, '(', 0, 1, ']');
  OMNIRIG_CHECK_POSITIVE(max_descriptor_distance);
  OMNIRIG_CHECK_NON_NEGATIVE(min_parallax_rad);
  OMNIRIG_CHECK_POSITIVE(max_range_m);
}

std::vector<StereoPoint> MatchStereo(const StereoRig& rig, const CameraFeatures& features0,
                                     const CameraFeatures& features1,
                                     const StereoMatchOptions& options) {
  options.Check();
  // Camera 1 of the epipolar convention is cam0, camera 2 is cam1.
  const Rigid3d cam1_from_cam0 = rig.cam0_from_cam1.Inverse();
  const Eigen::Matrix3d E = EssentialFromPose(cam1_from_cam0);
  const Eigen::Vector3d cam1_centre_in_cam0 = rig.cam0_from_cam1.translation;
  const int n0 = features0.size(), n1 = features1.size();
  // The epipolar plane normal of each cam0 bearing, in cam1: |b1 . n| is the sine of the
  // angle between b1 and the plane (eq. 16).
  std::vector<Eigen::Vector3d> normals(n0);
  for (int i = 0; i < n0; ++i) normals[i] = (E * features0.bearings[i]).normalized();
  const double max_sine = std::sin(options.max_epipolar_error_rad);
  const int dims = features0.descriptors.cols;
  std::vector<BestTwo> best0(n0), best1(n1);
  for (int i = 0; i < n0; ++i) {
    const float* d0 = features0.descriptors.ptr<float>(i);
    const Eigen::Vector3d& b0 = features0.bearings[i];
    for (int j = 0; j < n1; ++j) {
      if (std::abs(features1.bearings[j].dot(normals[i])) > max_sine) continue;
      // On the curve's right half: the cam1 ray, seen from cam0, must turn towards b0 from
      // the baseline (rays that meet behind a camera are on the other half of the circle).
      const Eigen::Vector3d b1_in_cam0 = rig.cam0_from_cam1.rotation * features1.bearings[j];
      if (b0.cross(b1_in_cam0).dot(b0.cross(cam1_centre_in_cam0)) > 0 &&
          b0.cross(b1_in_cam0).norm() > 1e-3) {
        continue;
      }
      const float d = SquaredDistance(d0, features1.descriptors.ptr<float>(j), dims);
      best0[i].Add(j, d);
      best1[j].Add(i, d);
    }
  }
  TriangulationOptions triangulation;
  triangulation.min_parallax_rad = options.min_parallax_rad;
  triangulation.max_angular_error_rad = 2 * options.max_epipolar_error_rad;
  triangulation.bearing_std_rad = 0.5 / rig.cam0.intrinsics.gamma_u();
  std::vector<StereoPoint> points;
  for (int i = 0; i < n0; ++i) {
    const int j = best0[i].best;
    if (!Passes(best0[i], options.max_descriptor_ratio, options.max_descriptor_distance) ||
        best1[j].best != i ||
        !Passes(best1[j], options.max_descriptor_ratio, options.max_descriptor_distance)) {
      continue;
    }
    const TriangulatedPoint point = TriangulateMidpoint(cam1_from_cam0, features0.bearings[i],
                                                        features1.bearings[j], triangulation);
    if (!point.valid || point.point_in_cam1.norm() > options.max_range_m) continue;
    points.push_back({i, j, point.point_in_cam1, point.range_std_m});
  }
  return points;
}

std::vector<std::pair<int, int>> MatchDescriptors(const cv::Mat& descriptors_a,
                                                  const cv::Mat& descriptors_b,
                                                  double max_ratio, double max_distance) {
  std::vector<std::pair<int, int>> matches;
  if (descriptors_a.rows < 2 || descriptors_b.rows < 2) return matches;
  cv::BFMatcher matcher(cv::NORM_L2);
  std::vector<std::vector<cv::DMatch>> ab, ba;
  matcher.knnMatch(descriptors_a, descriptors_b, ab, 2);
  matcher.knnMatch(descriptors_b, descriptors_a, ba, 2);
  std::vector<int> best_of_b(descriptors_b.rows, -1);
  for (const auto& m : ba) {
    if (m.size() == 2 && m[0].distance < max_ratio * m[1].distance) {
      best_of_b[m[0].queryIdx] = m[0].trainIdx;
    }
  }
  for (const auto& m : ab) {
    if (m.size() < 2 || !(m[0].distance < max_ratio * m[1].distance) ||
        m[0].distance > max_distance) {
      continue;
    }
    if (best_of_b[m[0].trainIdx] == m[0].queryIdx) matches.emplace_back(m[0].queryIdx, m[0].trainIdx);
  }
  return matches;
}

std::vector<std::pair<int, int>> MatchDescriptorsGated(const CameraFeatures& a,
                                                       const CameraFeatures& b,
                                                       const Eigen::Matrix3d& b_from_a_rotation,
                                                       double max_angle_rad, double max_ratio,
                                                       double max_distance) {
  const int na = a.size(), nb = b.size();
  std::vector<std::pair<int, int>> matches;
  if (na == 0 || nb == 0) return matches;
  // Bearings of b as contiguous floats: the gate is the inner loop's first and cheapest test.
  std::vector<float> bearings_b(3 * nb);
  for (int j = 0; j < nb; ++j) {
    for (int k = 0; k < 3; ++k) bearings_b[3 * j + k] = static_cast<float>(b.bearings[j][k]);
  }
  const float min_cos = static_cast<float>(std::cos(max_angle_rad));
  const int dims = a.descriptors.cols;
  std::vector<BestTwo> best_a(na), best_b(nb);
  for (int i = 0; i < na; ++i) {
    const Eigen::Vector3f r = (b_from_a_rotation * a.bearings[i]).cast<float>();
    const float* da = a.descriptors.ptr<float>(i);
    for (int j = 0; j < nb; ++j) {
      const float* bj = &bearings_b[3 * j];
      if (r.x() * bj[0] + r.y() * bj[1] + r.z() * bj[2] < min_cos) continue;
      const float d = SquaredDistance(da, b.descriptors.ptr<float>(j), dims);
      best_a[i].Add(j, d);
      best_b[j].Add(i, d);
    }
  }
  for (int i = 0; i < na; ++i) {
    const int j = best_a[i].best;
    if (Passes(best_a[i], max_ratio, max_distance) && best_b[j].best == i &&
        Passes(best_b[j], max_ratio, max_distance)) {
      matches.emplace_back(i, j);
    }
  }
  return matches;
}

std::vector<std::pair<int, int>> MatchDescriptorsInGroups(const cv::Mat& descriptors_a,
                                                          const std::vector<int>& group_a,
                                                          const cv::Mat& descriptors_b,
                                                          const std::vector<int>& group_b,
                                                          double max_ratio, double max_distance) {
  OMNIRIG_CHECK(descriptors_a.type() == CV_32F && descriptors_b.type() == CV_32F &&
                    descriptors_a.cols == descriptors_b.cols,
                "descriptors must be float rows of one size");
  OMNIRIG_CHECK(group_a.size() == static_cast<size_t>(descriptors_a.rows) &&
                    group_b.size() == static_cast<size_t>(descriptors_b.rows),
                "one group per descriptor");
  std::unordered_map<int, std::vector<int>> members_b;
  for (int j = 0; j < descriptors_b.rows; ++j) members_b[group_b[j]].push_back(j);
  const int dims = descriptors_a.cols;
  std::vector<BestTwo> best_a(descriptors_a.rows), best_b(descriptors_b.rows);
  for (int i = 0; i < descriptors_a.rows; ++i) {
    const auto group = members_b.find(group_a[i]);
    if (group == members_b.end()) continue;
    const float* da = descriptors_a.ptr<float>(i);
    for (int j : group->second) {
      const float d = SquaredDistance(da, descriptors_b.ptr<float>(j), dims);
      best_a[i].Add(j, d);
      best_b[j].Add(i, d);
    }
  }
  std::vector<std::pair<int, int>> matches;
  for (int i = 0; i < descriptors_a.rows; ++i) {
    const int j = best_a[i].best;
    if (Passes(best_a[i], max_ratio, max_distance) && best_b[j].best == i &&
        Passes(best_b[j], max_ratio, max_distance)) {
      matches.emplace_back(i, j);
    }
  }
  return matches;
}

}  // namespace omnirig
