#include "engine/geometry/rigid3.h"

#include <gtest/gtest.h>

namespace omnirig {
namespace {

TEST(Rigid3d, ComposeAndInverse) {
  const Rigid3d b_from_a(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())),
                         Eigen::Vector3d(0.1, -0.2, 0.5));
  const Rigid3d c_from_b(Eigen::Quaterniond(Eigen::AngleAxisd(-0.7, Eigen::Vector3d::UnitZ())),
                         Eigen::Vector3d(1, 2, 3));
  const Eigen::Vector3d point_in_a(0.4, 0.5, -0.6);
  const Rigid3d c_from_a = c_from_b * b_from_a;
  EXPECT_LT((c_from_a * point_in_a - c_from_b * (b_from_a * point_in_a)).norm(), 1e-12);
  EXPECT_LT((c_from_a.Inverse() * (c_from_a * point_in_a) - point_in_a).norm(), 1e-12);
}

TEST(Rigid3d, ParamsAndWxyzRoundTrip) {
  const Rigid3d pose(Eigen::Quaterniond(0.5, 0.5, -0.5, 0.5), Eigen::Vector3d(1, 2, 3));
  const auto params = pose.ToParams();
  const Rigid3d back = Rigid3d::FromParams(params.data());
  EXPECT_LT(RotationDistanceRad(pose.rotation, back.rotation), 1e-12);
  const auto wxyz = pose.ToWxyz();
  EXPECT_DOUBLE_EQ(wxyz[0], 0.5);
  EXPECT_DOUBLE_EQ(wxyz[2], -0.5);
  EXPECT_LT(RotationDistanceRad(Rigid3d::FromWxyz(wxyz), pose.rotation), 1e-12);
}

}  // namespace
}  // namespace omnirig
