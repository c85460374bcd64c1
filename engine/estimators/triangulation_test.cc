#include "engine/estimators/triangulation.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "engine/util/check.h"
#include "testing/geometry/random_bearing.h"

namespace omnirig {
namespace {

// A vertical rig with a 0.1 m baseline and a small relative rotation.
Rigid3d Rig() {
  return Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.05, Eigen::Vector3d(0.3, 1, 0.2).normalized())),
      Eigen::Vector3d(0.002, -0.001, -0.1));
}

using TriangulateFn = TriangulatedPoint (*)(const Rigid3d&, const Eigen::Vector3d&,
                                            const Eigen::Vector3d&, const TriangulationOptions&);

class Triangulation : public ::testing::TestWithParam<TriangulateFn> {};

TEST_P(Triangulation, ExactBearingsGiveTheExactPointAllAroundTheSphere) {
  const Rigid3d cam2_from_cam1 = Rig();
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> range(0.3, 3.0);
  int valid = 0;
  for (int i = 0; i < 500; ++i) {
    const Eigen::Vector3d point = range(rng) * RandomUnitVector(rng);
    const TriangulatedPoint t =
        GetParam()(cam2_from_cam1, point.normalized(), (cam2_from_cam1 * point).normalized(), {});
    if (!t.valid) {
      // Only low parallax (points near the baseline's line) may be rejected.
      EXPECT_EQ(t.reason, "parallax");
      continue;
    }
    ++valid;
    EXPECT_LT((t.point_in_cam1 - point).norm(), 1e-9 * point.norm()) << point.transpose();
    EXPECT_LT(t.angular_error1_rad, 1e-9);
    EXPECT_LT(t.angular_error2_rad, 1e-9);
  }
  EXPECT_GT(valid, 400);
}

TEST_P(Triangulation, RangeStdPredictsTheObservedRangeError) {
  // Board-like points 1 m away, 0.5 mrad noise on each bearing.
  const Rigid3d cam2_from_cam1 = Rig();
  std::mt19937_64 rng(2);
  TriangulationOptions options;
  options.bearing_std_rad = 5e-4;
  const Eigen::Vector3d point(0.9, 0.2, -0.4);
  double sum_sq = 0.0, predicted = 0.0;
  int n = 0;
  for (int i = 0; i < 4000; ++i) {
    const TriangulatedPoint t = GetParam()(
        cam2_from_cam1, PerturbBearing(point.normalized(), options.bearing_std_rad, rng),
        PerturbBearing((cam2_from_cam1 * point).normalized(), options.bearing_std_rad, rng),
        options);
    ASSERT_TRUE(t.valid) << t.reason;
    const double error = t.point_in_cam1.norm() - point.norm();
    sum_sq += error * error;
    predicted += t.range_std_m;
    ++n;
  }
  const double observed_std = std::sqrt(sum_sq / n);
  predicted /= n;
  // First-order prediction within 20% (the midpoint averages two rays, which the formula
  // for a single-ray perturbation does not credit, hence the asymmetric band).
  EXPECT_GT(observed_std, 0.5 * predicted);
  EXPECT_LT(observed_std, 1.2 * predicted);
  // Accuracy: 1 m away with a 0.1 m baseline, well under 1% of the range.
  EXPECT_LT(observed_std, 0.01 * point.norm());
}

TEST_P(Triangulation, RejectsLowParallaxAndPointsBehind) {
  const Rigid3d cam2_from_cam1 = Rig();
  TriangulationOptions options;
  options.min_parallax_rad = 0.01;
  // 100 m away with a 0.1 m baseline: parallax ~1 mrad.
  const Eigen::Vector3d far(100, 0, 5);
  const TriangulatedPoint t =
      GetParam()(cam2_from_cam1, far.normalized(), (cam2_from_cam1 * far).normalized(), options);
  EXPECT_FALSE(t.valid);
  EXPECT_EQ(t.reason, "parallax");
  EXPECT_LT(t.parallax_rad, 0.01);
  // The second bearing flipped: the rays meet behind camera 2.
  const Eigen::Vector3d near(0.5, 0.3, 0.2);
  const TriangulatedPoint behind =
      GetParam()(cam2_from_cam1, near.normalized(), -(cam2_from_cam1 * near).normalized(), options);
  EXPECT_FALSE(behind.valid);
  EXPECT_EQ(behind.reason, "behind");
  // Degenerate input is a value, not a crash.
  const TriangulatedPoint zero =
      GetParam()(cam2_from_cam1, Eigen::Vector3d::Zero(), near.normalized(), options);
  EXPECT_FALSE(zero.valid);
  const TriangulatedPoint no_baseline =
      GetParam()(Rigid3d(), near.normalized(), near.normalized(), options);
  EXPECT_FALSE(no_baseline.valid);
}

INSTANTIATE_TEST_SUITE_P(Methods, Triangulation,
                         ::testing::Values(&TriangulateMidpoint, &TriangulateOptimalAngular));

TEST(TriangulationOptimal, AngularErrorNeverExceedsTheMidpoints) {
  // The optimal method minimises the (sine-squared) angular error, so over noisy pairs its
  // summed squared angular errors are no larger than the midpoint's, pair by pair.
  const Rigid3d cam2_from_cam1 = Rig();
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> range(0.5, 3.0);
  TriangulationOptions options;
  options.min_parallax_rad = 0.0;
  int compared = 0;
  for (int i = 0; i < 500; ++i) {
    const Eigen::Vector3d point = range(rng) * RandomUnitVector(rng);
    const Eigen::Vector3d b1 = PerturbBearing(point.normalized(), 2e-3, rng);
    const Eigen::Vector3d b2 = PerturbBearing((cam2_from_cam1 * point).normalized(), 2e-3, rng);
    const TriangulatedPoint mid = TriangulateMidpoint(cam2_from_cam1, b1, b2, options);
    const TriangulatedPoint opt = TriangulateOptimalAngular(cam2_from_cam1, b1, b2, options);
    if (!mid.valid || !opt.valid) continue;
    const auto cost = [](const TriangulatedPoint& t) {
      return std::pow(std::sin(t.angular_error1_rad), 2) +
             std::pow(std::sin(t.angular_error2_rad), 2);
    };
    EXPECT_LE(cost(opt), cost(mid) * (1 + 1e-9) + 1e-18);
    ++compared;
  }
  EXPECT_GT(compared, 400);
}

TEST(TriangulationOptions, CheckRejectsInvalidOptions) {
  TriangulationOptions options;
  EXPECT_NO_THROW(options.Check());
  options.min_parallax_rad = -1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = TriangulationOptions{};
  options.max_angular_error_rad = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace omnirig
