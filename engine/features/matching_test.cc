#include "engine/features/matching.h"

#include <random>

#include <gtest/gtest.h>

namespace omnirig {
namespace {

StereoRig VerticalRig() {
  StereoRig rig;
  for (CameraModel* camera : {&rig.cam0, &rig.cam1}) {
    camera->width = 1024;
    camera->height = 768;
    camera->intrinsics.params = {0.9, 240, 240, 512, 384, 0, 0, 0, 0, 0, 0};
  }
  rig.cam0_from_cam1 = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.005, Eigen::Vector3d::UnitY())),
                               Eigen::Vector3d(0, 0, 0.1));
  return rig;
}

// The SLAM front end's policy: the epipolar angle in cam1, a descriptor distance bound, the
// rays' midpoint.
StereoMatchReport Match(const StereoRig& rig, const CameraFeatures& f0, const CameraFeatures& f1) {
  EpipolarMatchOptions matching;
  matching.max_epipolar_error_rad = 3e-3;
  matching.max_descriptor_distance = 250.0;
  StereoTriangulationOptions triangulation;
  triangulation.triangulation.min_parallax_rad = 0.004;
  triangulation.triangulation.max_angular_error_rad = 6e-3;
  triangulation.max_range_m = 30.0;
  return MatchStereo(rig.cam0_from_cam1, f0, f1, matching, triangulation);
}

// Features of random points around the rig seen by both cameras, with distinct random
// descriptors; cam1's features are shuffled.
void MakeFeatures(const StereoRig& rig, int n, CameraFeatures* f0, CameraFeatures* f1,
                  std::vector<Eigen::Vector3d>* points, std::vector<int>* cam1_of_point) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<int> order(n);
  for (int i = 0; i < n; ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);
  f0->descriptors.create(n, 128, CV_32F);
  f1->descriptors.create(n, 128, CV_32F);
  f1->bearings.resize(n);
  f1->pixels.resize(n);
  f0->rgb.assign(n, {0, 0, 0});
  f1->rgb.assign(n, {0, 0, 0});
  cam1_of_point->resize(n);
  const Rigid3d cam1_from_cam0 = rig.cam0_from_cam1.Inverse();
  for (int i = 0; i < n; ++i) {
    const double angle = M_PI * u(rng), range = 2 + 2 * (u(rng) + 1);
    points->emplace_back(range * std::cos(angle), range * std::sin(angle), 0.3 + 0.5 * u(rng));
    f0->bearings.push_back(points->back().normalized());
    f0->pixels.push_back(*Project(rig.cam0.intrinsics, points->back()));
    const int j = order[i];
    (*cam1_of_point)[i] = j;
    const Eigen::Vector3d in_cam1 = cam1_from_cam0 * points->back();
    f1->bearings[j] = in_cam1.normalized();
    f1->pixels[j] = *Project(rig.cam1.intrinsics, in_cam1);
    for (int k = 0; k < 128; ++k) {
      const float value = static_cast<float>(50 * (u(rng) + 1));
      f0->descriptors.at<float>(i, k) = value;
      f1->descriptors.at<float>(j, k) = value + static_cast<float>(2 * u(rng));
    }
  }
}

TEST(MatchStereo, FindsTheTrueMatchesAndTriangulatesThem) {
  const StereoRig rig = VerticalRig();
  CameraFeatures f0, f1;
  std::vector<Eigen::Vector3d> points;
  std::vector<int> cam1_of_point;
  MakeFeatures(rig, 300, &f0, &f1, &points, &cam1_of_point);
  const std::vector<StereoPoint> matches = Match(rig, f0, f1).points;
  EXPECT_GT(matches.size(), 280u);
  for (const StereoPoint& m : matches) {
    EXPECT_EQ(m.feature1, cam1_of_point[m.feature0]);
    EXPECT_LT((m.point_in_cam0 - points[m.feature0]).norm(),
              1e-6 * points[m.feature0].norm() + 1e-6);
  }
}

TEST(MatchStereo, RefusesDescriptorTwinsOffTheEpipolarCurve) {
  // cam1 sees nothing of cam0's points but holds the same descriptors at other bearings:
  // the epipolar constraint must reject every pairing.
  const StereoRig rig = VerticalRig();
  CameraFeatures f0, f1;
  std::vector<Eigen::Vector3d> points;
  std::vector<int> cam1_of_point;
  MakeFeatures(rig, 200, &f0, &f1, &points, &cam1_of_point);
  const Eigen::AngleAxisd turn(1.0, Eigen::Vector3d::UnitZ());
  for (Eigen::Vector3d& b : f1.bearings) b = turn * b;
  EXPECT_LT(Match(rig, f0, f1).points.size(), 5u);
}

TEST(MatchDescriptors, MutualRatioMatchesAndGatedAgree) {
  const StereoRig rig = VerticalRig();
  CameraFeatures f0, f1;
  std::vector<Eigen::Vector3d> points;
  std::vector<int> cam1_of_point;
  MakeFeatures(rig, 300, &f0, &f1, &points, &cam1_of_point);
  const auto exhaustive = MatchDescriptors(f0.descriptors, f1.descriptors, 0.8, 250);
  const auto gated = MatchDescriptorsGated(f0, f1, rig.cam0_from_cam1.rotation.conjugate().toRotationMatrix(), 0.2, 0.8, 250);
  EXPECT_GT(exhaustive.size(), 290u);
  EXPECT_GT(gated.size(), 290u);
  for (const auto& [a, b] : exhaustive) EXPECT_EQ(b, cam1_of_point[a]);
  for (const auto& [a, b] : gated) EXPECT_EQ(b, cam1_of_point[a]);
}

TEST(MatchDescriptors, InGroupsMatchesWithinAGroupOnly) {
  const StereoRig rig = VerticalRig();
  CameraFeatures f0, f1;
  std::vector<Eigen::Vector3d> points;
  std::vector<int> cam1_of_point;
  MakeFeatures(rig, 300, &f0, &f1, &points, &cam1_of_point);
  // Five groups; every tenth point of cam1 put into another group than its twin's.
  std::vector<int> group0(300), group1(300);
  for (int i = 0; i < 300; ++i) {
    group0[i] = i % 5;
    group1[cam1_of_point[i]] = i % 10 == 0 ? (i + 1) % 5 : i % 5;
  }
  const auto matches = MatchDescriptorsInGroups(f0.descriptors, group0, f1.descriptors, group1,
                                                0.8, 250);
  EXPECT_GT(matches.size(), 260u);
  EXPECT_LE(matches.size(), 270u);  // the 30 separated twins are not matched
  for (const auto& [a, b] : matches) {
    EXPECT_EQ(b, cam1_of_point[a]);
    EXPECT_EQ(group0[a], group1[b]);
  }
  // One group for all: the exhaustive search's matches.
  const auto one = MatchDescriptorsInGroups(f0.descriptors, std::vector<int>(300, 0),
                                            f1.descriptors, std::vector<int>(300, 0), 0.8, 250);
  EXPECT_EQ(one, MatchDescriptors(f0.descriptors, f1.descriptors, 0.8, 250));
}

}  // namespace
}  // namespace omnirig
