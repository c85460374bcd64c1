#include "engine/estimators/motion.h"

#include <cmath>

#include "engine/estimators/ransac.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
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

// The 3-point rigid alignment (Kabsch) as a RANSAC estimator (engine/estimators/ransac.h); a pair's
// error is its distance under the motion in units of its tolerance.
struct RigidMotionEstimator {
  using Model = Rigid3d;
  static constexpr int kMinSampleSize = 3;

  const std::vector<PointPair>& pairs;
  const ScaleOptions& options;

  void Estimate(const std::vector<int>& sample, std::vector<Model>* models) const {
    Refit(sample, &models->emplace_back());
  }
  bool Refit(const std::vector<int>& indices, Model* curr_from_prev) const {
    std::vector<Eigen::Vector3d> src, dst;
    for (const int i : indices) {
      src.push_back(pairs[i].point_in_prev);
      dst.push_back(pairs[i].point_in_curr);
    }
    *curr_from_prev = AlignRigid(src, dst);
    return true;
  }
  double Error(const Model& curr_from_prev, int i) const {
    return (curr_from_prev * pairs[i].point_in_prev - pairs[i].point_in_curr).norm() /
           Tolerance(pairs[i], options);
  }
  int NumData() const { return static_cast<int>(pairs.size()); }
};

}  // namespace

void ScaleOptions::Check() const {
  OMNIRIG_CHECK_POSITIVE(max_error_sigmas);
  OMNIRIG_CHECK_NON_NEGATIVE(min_tolerance_m);
  OMNIRIG_CHECK_AT_LEAST(min_inliers, 1);
  OMNIRIG_CHECK_AT_LEAST(max_iterations, 1);
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
  // All max_iterations hypotheses are tried; then two least-squares fits on the inliers (the
  // inlier set can grow after the first).
  RansacOptions ransac;
  ransac.max_error = 1.0;
  ransac.min_iterations = ransac.max_iterations = options.max_iterations;
  ransac.seed = options.seed;
  ransac.local_optimization = false;
  const RigidMotionEstimator estimator{pairs, options};
  const RansacReport<Rigid3d> found = Ransac(estimator, ransac);
  report.curr_from_prev = found.model;
  report.inlier_mask = found.inlier_mask;
  report.num_inliers = found.num_inliers;
  for (int round = 0; round < 2 && report.num_inliers >= 3; ++round) {
    std::vector<int> inliers;
    for (int i = 0; i < n; ++i) {
      if (report.inlier_mask[i]) inliers.push_back(i);
    }
    estimator.Refit(inliers, &report.curr_from_prev);
    report.inlier_mask = Inliers(report.curr_from_prev, pairs, options, &report.num_inliers);
  }
  report.success = report.num_inliers >= std::max(3, options.min_inliers);
  if (!report.success) {
    report.reason = "3D-3D: only " + std::to_string(report.num_inliers) + " consistent stereo points";
  }
  return report;
}

Rigid3d AlignRigid(const std::vector<Eigen::Vector3d>& src,
                   const std::vector<Eigen::Vector3d>& dst) {
  OMNIRIG_CHECK(!src.empty() && src.size() == dst.size(),
                "AlignRigid needs two equally long, non-empty point lists");
  const double n = static_cast<double>(src.size());
  Eigen::Vector3d mean_src = Eigen::Vector3d::Zero(), mean_dst = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < src.size(); ++i) {
    mean_src += src[i] / n;
    mean_dst += dst[i] / n;
  }
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < src.size(); ++i) {
    covariance += (dst[i] - mean_dst) * (src[i] - mean_src).transpose();
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance,
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  // Umeyama's sign correction keeps a proper rotation when the best orthogonal fit reflects.
  Eigen::Matrix3d s = Eigen::Matrix3d::Identity();
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0) s(2, 2) = -1;
  const Eigen::Matrix3d rotation = svd.matrixU() * s * svd.matrixV().transpose();
  return Rigid3d(Eigen::Quaterniond(rotation), mean_dst - rotation * mean_src);
}

}  // namespace omnirig
