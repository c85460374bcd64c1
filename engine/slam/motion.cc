#include "engine/slam/motion.h"

#include <cmath>
#include <random>

#include "engine/slam/evaluation.h"
#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

double Tolerance(const PointPair& pair, const ScaleOptions& options) {
  return options.min_tolerance_m +
         options.max_error_sigmas * std::hypot(pair.std_prev_m, pair.std_curr_m);
}

std::vector<char> Inliers(const Rigid3d& curr_from_prev, const std::vector<PointPair>& pairs,
                          const ScaleOptions& options, int* count) {
  std::vector<char> mask(pairs.size(), 0);
  *count = 0;
  for (size_t i = 0; i < pairs.size(); ++i) {
    const double e = (curr_from_prev * pairs[i].point_in_prev - pairs[i].point_in_curr).norm();
    if (e < Tolerance(pairs[i], options)) {
      mask[i] = 1;
      ++*count;
    }
  }
  return mask;
}

}  // namespace

void ScaleOptions::Check() const {
  OMNIRIG_CHECK(max_error_sigmas > 0, "max_error_sigmas must be positive");
  OMNIRIG_CHECK(min_tolerance_m >= 0, "min_tolerance_m must not be negative");
  OMNIRIG_CHECK(min_inliers >= 1, "min_inliers must be at least 1");
  OMNIRIG_CHECK(max_iterations >= 1, "max_iterations must be at least 1");
}

ScaleReport EstimateScale(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& t_unit,
                          const std::vector<PointPair>& pairs, const ScaleOptions& options) {
  options.Check();
  ScaleReport report;
  if (static_cast<int>(pairs.size()) < options.min_inliers) {
    report.reason = "too few stereo points seen in both frames (" +
                    std::to_string(pairs.size()) + ")";
    return report;
  }
  const Eigen::Vector3d direction = t_unit.normalized();
  const Eigen::Quaterniond q(rotation);
  std::vector<double> votes(pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) {
    votes[i] = (pairs[i].point_in_curr - rotation * pairs[i].point_in_prev).dot(direction);
  }
  // Every vote is a one-point hypothesis; with a few hundred pairs trying them all is cheap.
  int best_count = -1;
  for (size_t h = 0; h < pairs.size(); ++h) {
    int count = 0;
    const Rigid3d hypothesis(q, votes[h] * direction);
    Inliers(hypothesis, pairs, options, &count);
    if (count > best_count) {
      best_count = count;
      report.scale_m = votes[h];
    }
  }
  // Weighted mean over the inliers, twice (the inlier set can grow after the first mean).
  for (int round = 0; round < 2; ++round) {
    report.inlier_mask = Inliers(Rigid3d(q, report.scale_m * direction), pairs, options,
                                 &report.num_inliers);
    double sum = 0, weight_sum = 0;
    for (size_t i = 0; i < pairs.size(); ++i) {
      if (!report.inlier_mask[i]) continue;
      const double sigma = Tolerance(pairs[i], options) / options.max_error_sigmas;
      sum += votes[i] / (sigma * sigma);
      weight_sum += 1 / (sigma * sigma);
    }
    if (weight_sum > 0) report.scale_m = sum / weight_sum;
  }
  report.translation_m = report.scale_m * direction;
  report.success = report.num_inliers >= options.min_inliers;
  if (!report.success) {
    report.reason = "scale: only " + std::to_string(report.num_inliers) + " consistent stereo points";
  }
  return report;
}

AbsoluteOrientationReport EstimateRigidMotion3D(const std::vector<PointPair>& pairs,
                                                const ScaleOptions& options) {
  options.Check();
  AbsoluteOrientationReport report;
  const int n = static_cast<int>(pairs.size());
  if (n < std::max(3, options.min_inliers)) {
    report.reason = "too few stereo points seen in both frames (" + std::to_string(n) + ")";
    return report;
  }
  std::mt19937_64 rng(options.seed);
  std::uniform_int_distribution<int> pick(0, n - 1);
  int best_count = -1;
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    const int a = pick(rng), b = pick(rng), c = pick(rng);
    if (a == b || b == c || a == c) continue;
    const Rigid3d hypothesis =
        AlignRigid({pairs[a].point_in_prev, pairs[b].point_in_prev, pairs[c].point_in_prev},
                   {pairs[a].point_in_curr, pairs[b].point_in_curr, pairs[c].point_in_curr});
    int count = 0;
    std::vector<char> mask = Inliers(hypothesis, pairs, options, &count);
    if (count > best_count) {
      best_count = count;
      report.curr_from_prev = hypothesis;
      report.inlier_mask = std::move(mask);
    }
  }
  for (int round = 0; round < 2 && best_count >= 3; ++round) {
    std::vector<Eigen::Vector3d> src, dst;
    for (int i = 0; i < n; ++i) {
      if (!report.inlier_mask[i]) continue;
      src.push_back(pairs[i].point_in_prev);
      dst.push_back(pairs[i].point_in_curr);
    }
    report.curr_from_prev = AlignRigid(src, dst);
    report.inlier_mask = Inliers(report.curr_from_prev, pairs, options, &best_count);
  }
  report.num_inliers = std::max(0, best_count);
  report.success = report.num_inliers >= std::max(3, options.min_inliers);
  if (!report.success) {
    report.reason = "3D-3D: only " + std::to_string(report.num_inliers) + " consistent stereo points";
  }
  return report;
}

}  // namespace omnirig::slam
