#include "engine/features/matching.h"

#include <algorithm>
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

// The pairs (i, best_a[i].best) that pass the ratio test and max_distance both ways.
std::vector<std::pair<int, int>> MutualBest(const std::vector<BestTwo>& best_a,
                                            const std::vector<BestTwo>& best_b, double ratio,
                                            double max_distance) {
  std::vector<std::pair<int, int>> matches;
  for (int i = 0; i < static_cast<int>(best_a.size()); ++i) {
    const int j = best_a[i].best;
    if (Passes(best_a[i], ratio, max_distance) && best_b[j].best == i &&
        Passes(best_b[j], ratio, max_distance)) {
      matches.emplace_back(i, j);
    }
  }
  return matches;
}

// OpenCV's vectorised kernel: the compiler may not reorder a float sum into SIMD lanes.
float SquaredDistance(const float* a, const float* b, int n) {
  return cv::hal::normL2Sqr_(a, b, n);
}

}  // namespace

void EpipolarMatchOptions::Check() const {
  OMNIRIG_CHECK_POSITIVE(max_epipolar_error_rad);
  OMNIRIG_CHECK_IN(max_descriptor_ratio, '(', 0, 1, ']');
  // Infinity (no bound) passes: these are upper bounds.
  OMNIRIG_CHECK(max_descriptor_distance > 0,
                "max_descriptor_distance must be positive, got " << max_descriptor_distance);
}

void StereoTriangulationOptions::Check() const {
  triangulation.Check();
  OMNIRIG_CHECK(max_range_m > 0, "max_range_m must be positive, got " << max_range_m);
  OMNIRIG_CHECK(max_relative_range_std > 0,
                "max_relative_range_std must be positive, got " << max_relative_range_std);
}

namespace {

// The pairs on each other's epipolar curves, as each feature's best two candidates by
// descriptor distance, with the epipolar error (its sine) of each cam0 feature's best.
struct EpipolarCandidates {
  std::vector<BestTwo> best0, best1;
  std::vector<double> best0_sine;
  int count = 0;
};

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

Eigen::Vector3d UnitOrZero(const Eigen::Vector3d& v) {
  const double n = v.norm();
  return n > 1e-9 ? Eigen::Vector3d(v / n) : Eigen::Vector3d::Zero();
}

EpipolarCandidates FindEpipolarCandidates(const Rigid3d& cam0_from_cam1,
                                          const CameraFeatures& features0,
                                          const CameraFeatures& features1,
                                          const EpipolarMatchOptions& options) {
  const int n0 = features0.size(), n1 = features1.size();
  EpipolarCandidates candidates;
  candidates.best0.resize(n0);
  candidates.best1.resize(n1);
  candidates.best0_sine.resize(n0);
  // Unit normals of the epipolar planes: of b0 in cam1 (E b0) and of b1 in cam0 (E^T b1); |b .
  // n| is the sine of the angle between a bearing and the plane (eq. 16). A bearing along the
  // baseline has no plane (and no depth): it gets a zero normal and no candidates.
  const Eigen::Matrix3d e = EssentialFromPose(cam0_from_cam1.Inverse());
  std::vector<Eigen::Vector3d> normals_in1(n0), normals_in0(n1), rays1_in0(n1);
  for (int i = 0; i < n0; ++i) normals_in1[i] = UnitOrZero(e * features0.bearings[i]);
  for (int j = 0; j < n1; ++j) {
    normals_in0[j] = UnitOrZero(e.transpose() * features1.bearings[j]);
    rays1_in0[j] = cam0_from_cam1.rotation * features1.bearings[j];
  }
  const Eigen::Vector3d& c1_in0 = cam0_from_cam1.translation;
  const double sin_max = std::sin(options.max_epipolar_error_rad);
  const int dims = features0.descriptors.cols;
  for (int i = 0; i < n0; ++i) {
    if (normals_in1[i].isZero()) continue;
    const Eigen::Vector3d& b0 = features0.bearings[i];
    const float* desc0 = features0.descriptors.ptr<float>(i);
    for (int j = 0; j < n1; ++j) {
      const double s1 = std::abs(normals_in1[i].dot(features1.bearings[j]));
      if (s1 > sin_max) continue;
      double sine = s1;
      if (options.check_both_cameras) {
        const double s0 = std::abs(normals_in0[j].dot(b0));
        if (s0 > sin_max || normals_in0[j].isZero()) continue;
        if (!MeetInFront(c1_in0, b0, rays1_in0[j])) continue;
        sine = std::max(s0, s1);
      } else {
        // On the curve's near half: cam1's ray, seen from cam0, must turn towards b0 from the
        // baseline (rays that meet behind a camera are on the other half of the circle).
        const Eigen::Vector3d turn = b0.cross(rays1_in0[j]);
        if (turn.dot(b0.cross(c1_in0)) > 0 && turn.norm() > 1e-3) continue;
      }
      const float d = SquaredDistance(desc0, features1.descriptors.ptr<float>(j), dims);
      candidates.best0[i].Add(j, d);
      candidates.best1[j].Add(i, d);
      if (candidates.best0[i].best == j) candidates.best0_sine[i] = sine;
      ++candidates.count;
    }
  }
  return candidates;
}

// Triangulates feature0 i with feature1 j into report->points, or counts why not.
void AddStereoPoint(const Rigid3d& cam1_from_cam0, const CameraFeatures& features0,
                    const CameraFeatures& features1, int i, int j, double epipolar_error_rad,
                    const StereoTriangulationOptions& options, StereoMatchReport* report) {
  const TriangulatedPoint t =
      options.optimal_angular
          ? TriangulateOptimalAngular(cam1_from_cam0, features0.bearings[i], features1.bearings[j],
                                      options.triangulation)
          : TriangulateMidpoint(cam1_from_cam0, features0.bearings[i], features1.bearings[j],
                                options.triangulation);
  if (!t.valid) {
    (t.reason == "parallax" ? report->num_rejected_parallax : report->num_rejected_reprojection)++;
    return;
  }
  const double range_m = t.point_in_cam1.norm();
  if (range_m > options.max_range_m || t.range_std_m > options.max_relative_range_std * range_m) {
    ++report->num_rejected_range;
    return;
  }
  StereoPoint point;
  point.feature0 = i;
  point.feature1 = j;
  point.point_in_cam0 = t.point_in_cam1;  // the triangulation's camera 1 is cam0
  point.range_std_m = t.range_std_m;
  point.parallax_rad = t.parallax_rad;
  point.epipolar_error_rad = epipolar_error_rad;
  point.pixel0 = features0.pixels[i];
  point.rgb = features0.rgb[i];
  report->points.push_back(point);
}

void CheckFeatures(const CameraFeatures& features) {
  const size_t n = features.bearings.size();
  OMNIRIG_CHECK(features.pixels.size() == n && features.rgb.size() == n &&
                    static_cast<size_t>(features.descriptors.rows) == n &&
                    (n == 0 || features.descriptors.type() == CV_32F),
                "features need one pixel, colour and float descriptor row per bearing");
}

}  // namespace

StereoMatchReport MatchStereo(const Rigid3d& cam0_from_cam1, const CameraFeatures& features0,
                              const CameraFeatures& features1, const EpipolarMatchOptions& matching,
                              const StereoTriangulationOptions& triangulation) {
  matching.Check();
  triangulation.Check();
  CheckFeatures(features0);
  CheckFeatures(features1);
  StereoMatchReport report;
  if (features0.size() == 0 || features1.size() == 0) return report;
  OMNIRIG_CHECK(features0.descriptors.cols == features1.descriptors.cols,
                "descriptor sizes differ between the two images");
  const EpipolarCandidates candidates =
      FindEpipolarCandidates(cam0_from_cam1, features0, features1, matching);
  report.num_candidates = candidates.count;
  const Rigid3d cam1_from_cam0 = cam0_from_cam1.Inverse();
  for (int i = 0; i < features0.size(); ++i) {
    const int j = candidates.best0[i].best;
    if (!Passes(candidates.best0[i], matching.max_descriptor_ratio,
                matching.max_descriptor_distance)) {
      continue;
    }
    if (matching.mutual_check && (candidates.best1[j].best != i ||
                                  !Passes(candidates.best1[j], matching.max_descriptor_ratio,
                                          matching.max_descriptor_distance))) {
      continue;
    }
    ++report.num_matches;
    AddStereoPoint(cam1_from_cam0, features0, features1, i, j, std::asin(candidates.best0_sine[i]),
                   triangulation, &report);
  }
  return report;
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
  return MutualBest(best_a, best_b, max_ratio, max_distance);
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
  return MutualBest(best_a, best_b, max_ratio, max_distance);
}

}  // namespace omnirig
