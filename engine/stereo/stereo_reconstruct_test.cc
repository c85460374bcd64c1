#include "engine/stereo/stereo_reconstruct.h"

#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "engine/geometry/unified_camera.h"
#include "engine/util/check.h"

namespace omnirig {
namespace {

CameraModel Camera(double u0, double v0) {
  CameraModel camera;
  camera.intrinsics.params = {0.94, 240.0, 241.0, u0, v0, 0.0, -0.06, 0.012, 0.0005, -0.0003, 0.0};
  camera.width = 1024;
  camera.height = 768;
  return camera;
}

// A vertical rig: cam1 100 mm along cam0's +z axis, slightly turned.
StereoRig Rig() {
  StereoRig rig;
  rig.cam0 = Camera(514.0, 380.0);
  rig.cam1 = Camera(509.0, 387.0);
  rig.cam0_from_cam1 =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.005, Eigen::Vector3d(1, 1, 0.3).normalized())),
              Eigen::Vector3d(0.0, 0.0, 0.1));
  return rig;
}

// Features of points around the rig, each with a random descriptor seen (with a little noise)
// by both cameras, in shuffled order; returns the true cam0 -> cam1 index map.
struct SyntheticFeatures {
  CameraFeatures f0, f1;
  std::vector<int> true_match_of0;  // -1 when the point is not seen by cam1
};

cv::Mat RandomDescriptor(std::mt19937_64& rng) {
  std::uniform_real_distribution<float> u(0.f, 1.f);
  cv::Mat d(1, 128, CV_32F);
  for (int k = 0; k < 128; ++k) d.at<float>(0, k) = u(rng);
  return d;
}

SyntheticFeatures MakeFeatures(const StereoRig& rig, int n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::normal_distribution<float> noise(0.f, 0.02f);
  std::uniform_real_distribution<double> range(1.0, 4.0);
  SyntheticFeatures s;
  const Rigid3d cam1_from_cam0 = rig.cam0_from_cam1.Inverse();
  std::vector<std::pair<Eigen::Vector3d, cv::Mat>> seen_by_1;
  std::vector<int> owner;
  for (int k = 0; k < n; ++k) {
    // Points around the horizon band, as a catadioptric sensor sees them.
    const Eigen::Vector3d dir = Eigen::Vector3d(g(rng), g(rng), 0.3 * g(rng)).normalized();
    const Eigen::Vector3d p0 = range(rng) * dir;
    const cv::Mat desc = RandomDescriptor(rng);
    s.f0.bearings.push_back(p0.normalized());
    s.f0.pixels.emplace_back(0, 0);
    s.f0.rgb.push_back({0, 0, 0});
    s.f0.descriptors.push_back(desc);
    s.true_match_of0.push_back(-1);
    if (k % 5 == 4) continue;  // every fifth point is occluded in cam1
    cv::Mat noisy = desc.clone();
    for (int c = 0; c < 128; ++c) noisy.at<float>(0, c) += noise(rng);
    seen_by_1.emplace_back((cam1_from_cam0 * p0).normalized(), noisy);
    owner.push_back(k);
  }
  std::vector<int> order(seen_by_1.size());
  for (size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
  std::shuffle(order.begin(), order.end(), rng);
  for (size_t pos = 0; pos < order.size(); ++pos) {
    s.f1.bearings.push_back(seen_by_1[order[pos]].first);
    s.f1.pixels.emplace_back(0, 0);
    s.f1.rgb.push_back({0, 0, 0});
    s.f1.descriptors.push_back(seen_by_1[order[pos]].second);
    s.true_match_of0[owner[order[pos]]] = static_cast<int>(pos);
  }
  return s;
}

// MatchStereo (engine/features/matching.h) with the sparse reconstruction's options.
StereoMatchReport Match(const StereoRig& rig, const CameraFeatures& f0, const CameraFeatures& f1,
                        const StereoReconstructOptions& options = {}) {
  return MatchStereo(rig.cam0_from_cam1, f0, f1, options.Matching(), options.Triangulation(rig));
}

TEST(StereoMatching, MatchesFollowTheEpipolarConstraint) {
  const StereoRig rig = Rig();
  const SyntheticFeatures s = MakeFeatures(rig, 500, 1);
  StereoReconstructOptions options;
  const StereoMatchReport report = Match(rig, s.f0, s.f1, options);
  int correct = 0;
  for (const StereoPoint& p : report.points) {
    correct += s.true_match_of0[p.feature0] == p.feature1;
    EXPECT_LE(p.epipolar_error_rad, options.max_epipolar_error_rad);
  }
  EXPECT_EQ(correct, static_cast<int>(report.points.size()));  // no wrong match
  EXPECT_GT(report.num_matches, 390);                          // of 400 visible points
  EXPECT_GT(correct, 350);  // triangulated within the parallax and uncertainty limits
  // The constraint prunes: far fewer candidates than all 500 x 400 pairs.
  EXPECT_LT(report.num_candidates, 500 * 400 / 20);
}

TEST(StereoMatching, EpipolarConstraintResolvesRepeatedTexture) {
  // Two features in cam1 with the same descriptor (repeated texture): a plain ratio test would
  // reject both, the epipolar constraint keeps only the one on the curve.
  const StereoRig rig = Rig();
  const Rigid3d cam1_from_cam0 = rig.cam0_from_cam1.Inverse();
  std::mt19937_64 rng(2);
  const cv::Mat desc = RandomDescriptor(rng);
  const Eigen::Vector3d point(1.5, 0.4, 0.2);
  CameraFeatures f0, f1;
  f0.bearings = {point.normalized()};
  f0.pixels = {Eigen::Vector2d(0, 0)};
  f0.rgb = {{0, 0, 0}};
  f0.descriptors = desc.clone();
  const Eigen::Vector3d elsewhere = Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()) * point;
  f1.bearings = {(cam1_from_cam0 * elsewhere).normalized(), (cam1_from_cam0 * point).normalized()};
  f1.pixels = {Eigen::Vector2d(0, 0), Eigen::Vector2d(0, 0)};
  f1.rgb = {{0, 0, 0}, {0, 0, 0}};
  f1.descriptors.push_back(desc);
  f1.descriptors.push_back(desc);
  const StereoMatchReport report = Match(rig, f0, f1);
  ASSERT_EQ(report.points.size(), 1u);
  EXPECT_EQ(report.points[0].feature1, 1);
  EXPECT_LT((report.points[0].point_in_cam0 - point).norm(), 1e-6);
  // The antipodal half of the epipolar great circle is not the curve: a feature there does
  // not match (the rays would meet behind the cameras).
  f1.bearings = {-(cam1_from_cam0 * point).normalized()};
  f1.descriptors = desc.clone();
  f1.pixels.resize(1);
  f1.rgb.resize(1);
  EXPECT_EQ(Match(rig, f0, f1).num_candidates, 0);
  // Empty inputs give no matches.
  EXPECT_TRUE(Match(rig, CameraFeatures{}, f1).points.empty());
}

TEST(StereoReconstruct, ImageSizeMismatchIsAnError) {
  const StereoRig rig = Rig();
  const cv::Mat small(100, 100, CV_8UC3, cv::Scalar(0, 0, 0));
  const cv::Mat right(768, 1024, CV_8UC3, cv::Scalar(0, 0, 0));
  EXPECT_THROW(ReconstructStereoPair(rig, small, right, {}), InvalidArgument);
  EXPECT_THROW(ReconstructStereoPair(rig, right, small, {}), InvalidArgument);
  // All-dark images: nothing to match, an empty report rather than an error (small images
  // keep SIFT's pyramid cheap under the sanitizers).
  StereoRig small_rig = rig;
  small_rig.cam0.width = small_rig.cam1.width = 320;
  small_rig.cam0.height = small_rig.cam1.height = 240;
  const cv::Mat dark(240, 320, CV_8UC3, cv::Scalar(0, 0, 0));
  const StereoPairReport report = ReconstructStereoPair(small_rig, dark, dark, {});
  EXPECT_EQ(report.num_keypoints0, 0);
  EXPECT_TRUE(report.points.empty());
  StereoReconstructOptions bad;
  bad.ratio_test = 1.5;
  EXPECT_THROW(bad.Check(), InvalidArgument);
}

// The points as a PLY cloud (the file format: engine/geometry/ply_test.cc).
TEST(StereoReconstruct, SparseCloudHoldsPositionsAndColours) {
  std::vector<StereoPoint> points(2);
  points[0].point_in_cam0 = Eigen::Vector3d(1.5, -2.25, 3.0);
  points[0].rgb = {10, 20, 30};
  points[1].point_in_cam0 = Eigen::Vector3d(0.0, 0.5, -1.0);
  points[1].rgb = {255, 0, 128};
  const PlyCloud cloud = SparseCloud(points);
  EXPECT_EQ(cloud.positions,
            (std::vector<Eigen::Vector3f>{{1.5f, -2.25f, 3.0f}, {0.0f, 0.5f, -1.0f}}));
  EXPECT_EQ(cloud.colours, (std::vector<std::array<uint8_t, 3>>{{10, 20, 30}, {255, 0, 128}}));
  EXPECT_FALSE(cloud.has_confidence);
  EXPECT_NE(cloud.comment.find("cam0's frame, metres"), std::string::npos);
  cloud.Check();
}

}  // namespace
}  // namespace omnirig
