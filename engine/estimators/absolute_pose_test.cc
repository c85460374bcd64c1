// Relocalisation's absolute pose (absolute_pose.cc, OpenGV P3P + RANSAC): the pose from bearings
// with outliers, the same result for the same seed, and too few correspondences refused.

#include <random>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "engine/estimators/absolute_pose.h"

namespace omnirig {
namespace {

TEST(AbsolutePose, RecoversThePoseFromBearingsWithOutliersRepeatably) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  const Rigid3d rig_from_world(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.2, 0.3, 1).normalized())),
      Eigen::Vector3d(0.5, -1.0, 0.2));
  std::vector<Eigen::Vector3d> bearings, points;
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d point(5 * u(rng), 5 * u(rng), 2 * u(rng));  // all around the rig
    points.push_back(point);
    Eigen::Vector3d bearing = (rig_from_world * point).normalized();
    if (i % 3 == 0) bearing = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();  // outlier
    bearings.push_back(bearing);
  }
  AbsolutePoseOptions options;
  options.seed = 11;
  const AbsolutePoseReport a = EstimateAbsolutePose(bearings, points, options);
  ASSERT_TRUE(a.success) << a.reason;
  EXPECT_GE(a.num_inliers, 130);
  EXPECT_LT((a.rig_from_world.translation - rig_from_world.translation).norm(), 1e-6);
  EXPECT_LT(a.rig_from_world.rotation.angularDistance(rig_from_world.rotation), 1e-6);
  const AbsolutePoseReport b = EstimateAbsolutePose(bearings, points, options);
  EXPECT_EQ(a.inlier_mask, b.inlier_mask);
  EXPECT_EQ(a.rig_from_world.translation, b.rig_from_world.translation);
}

TEST(AbsolutePose, TooFewCorrespondencesAreAnAnswerNotAnError) {
  const std::vector<Eigen::Vector3d> three(3, Eigen::Vector3d::UnitX());
  const AbsolutePoseReport report = EstimateAbsolutePose(three, three, AbsolutePoseOptions());
  EXPECT_FALSE(report.success);
  EXPECT_FALSE(report.reason.empty());
}

}  // namespace
}  // namespace omnirig
