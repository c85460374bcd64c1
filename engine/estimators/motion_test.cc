#include "engine/estimators/motion.h"

#include <random>

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig {
namespace {

// Stereo points around the rig seen at two frames related by curr_from_prev, with range noise
// growing with distance (as a 100 mm baseline gives) and a share of gross mismatches.
std::vector<PointPair> MakePairs(const Rigid3d& curr_from_prev, int n, double outlier_share,
                                 std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::normal_distribution<double> unit_noise(0, 1);
  std::vector<PointPair> pairs;
  for (int i = 0; i < n; ++i) {
    const double angle = M_PI * u(rng), range = 2.5 + 1.5 * u(rng);
    const Eigen::Vector3d point(range * std::cos(angle), range * std::sin(angle), 0.8 * u(rng));
    PointPair pair;
    pair.std_prev_m = 0.004 * range * range;
    pair.std_curr_m = pair.std_prev_m;
    const Eigen::Vector3d in_curr = curr_from_prev * point;
    // Range noise along the line of sight.
    pair.point_in_prev = point + point.normalized() * pair.std_prev_m * unit_noise(rng);
    pair.point_in_curr = in_curr + in_curr.normalized() * pair.std_curr_m * unit_noise(rng);
    if ((u(rng) + 1) / 2 < outlier_share) {
      pair.point_in_curr += Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized() * (0.3 + (u(rng) + 1));
    }
    pairs.push_back(pair);
  }
  return pairs;
}

const Rigid3d kMotion(Eigen::Quaterniond(Eigen::AngleAxisd(0.08, Eigen::Vector3d(0.1, 0.2, 1).normalized())),
                      Eigen::Vector3d(0.12, -0.07, 0.01));

TEST(EstimateScale, RecoversTheMetricStepAlongTheEssentialDirection) {
  const std::vector<PointPair> pairs = MakePairs(kMotion, 400, 0.3, 1);
  ScaleOptions options;
  const ScaleReport report = EstimateScale(kMotion.RotationMatrix(),
                                           kMotion.translation.normalized(), pairs, options);
  ASSERT_TRUE(report.success) << report.reason;
  EXPECT_NEAR(report.scale_m, kMotion.translation.norm(), 0.002);
  EXPECT_LT((report.translation_m - kMotion.translation).norm(), 0.002);
  EXPECT_GT(report.num_inliers, 230);
  EXPECT_LT(report.num_inliers, 330);
}

TEST(EstimateScale, OnePointWouldNotDo) {
  // The robust estimate beats the paper's single-point eq. (18) by far on noisy points.
  const std::vector<PointPair> pairs = MakePairs(kMotion, 300, 0.0, 2);
  const ScaleReport report = EstimateScale(kMotion.RotationMatrix(),
                                           kMotion.translation.normalized(), pairs, ScaleOptions());
  double worst_single = 0;
  for (const PointPair& pair : pairs) {
    const double single = (pair.point_in_curr - kMotion.rotation * pair.point_in_prev)
                              .dot(kMotion.translation.normalized());
    worst_single = std::max(worst_single, std::abs(single - kMotion.translation.norm()));
  }
  EXPECT_LT(std::abs(report.scale_m - kMotion.translation.norm()), worst_single / 10);
}

TEST(EstimateScale, ReportsTooFewPairs) {
  const ScaleReport report = EstimateScale(Eigen::Matrix3d::Identity(), Eigen::Vector3d::UnitX(),
                                           MakePairs(kMotion, 3, 0, 3), ScaleOptions());
  EXPECT_FALSE(report.success);
  EXPECT_FALSE(report.reason.empty());
}

TEST(EstimateRigidMotion3D, RecoversRotationAndTranslationWithOutliers) {
  const std::vector<PointPair> pairs = MakePairs(kMotion, 400, 0.3, 4);
  ScaleOptions options;
  options.seed = 9;
  const AbsoluteOrientationReport report = EstimateRigidMotion3D(pairs, options);
  ASSERT_TRUE(report.success) << report.reason;
  EXPECT_LT((report.curr_from_prev.translation - kMotion.translation).norm(), 0.01);
  EXPECT_LT(RotationDistanceRad(report.curr_from_prev.rotation, kMotion.rotation), 0.003);
  // Same seed, same answer.
  const AbsoluteOrientationReport again = EstimateRigidMotion3D(pairs, options);
  EXPECT_EQ(again.num_inliers, report.num_inliers);
  EXPECT_EQ(again.curr_from_prev.translation, report.curr_from_prev.translation);
}

TEST(ScaleOptions, RejectsNonsense) {
  ScaleOptions options;
  options.min_inliers = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace omnirig
