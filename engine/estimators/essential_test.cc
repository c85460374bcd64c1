#include "engine/estimators/essential.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "engine/util/check.h"
#include "testing/geometry/random_bearing.h"

namespace omnirig {
namespace {

Rigid3d RandomPose(std::mt19937_64& rng, const Eigen::Vector3d& translation) {
  std::uniform_real_distribution<double> angle(-0.6, 0.6);
  const Eigen::Quaterniond q(Eigen::AngleAxisd(angle(rng), RandomUnitVector(rng)));
  return Rigid3d(q, translation);
}

struct Correspondences {
  std::vector<Eigen::Vector3d> bearings1, bearings2;
  std::vector<char> is_inlier;
};

// Points all around camera 1 (the whole sphere, 1-10 units away), seen by both cameras;
// a fraction of pairs replaced by unrelated bearings.
Correspondences MakeCorrespondences(const Rigid3d& cam2_from_cam1, int n, double noise_rad,
                                    double outlier_ratio, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> range(1.0, 10.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Correspondences c;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d point_in_cam1 = range(rng) * RandomUnitVector(rng);
    const Eigen::Vector3d point_in_cam2 = cam2_from_cam1 * point_in_cam1;
    if (point_in_cam2.norm() < 0.3) {
      --i;
      continue;
    }
    const bool outlier = unit(rng) < outlier_ratio;
    c.bearings1.push_back(PerturbBearing(point_in_cam1.normalized(), noise_rad, rng));
    c.bearings2.push_back(outlier ? RandomUnitVector(rng)
                                  : PerturbBearing(point_in_cam2.normalized(), noise_rad, rng));
    c.is_inlier.push_back(!outlier);
  }
  return c;
}

double TranslationAngle(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

TEST(Essential, EightPointOnExactBearingsRecoversE) {
  std::mt19937_64 rng(3);
  const Rigid3d truth = RandomPose(rng, Eigen::Vector3d(0.3, -0.2, 0.9).normalized());
  const Correspondences c = MakeCorrespondences(truth, 50, 0.0, 0.0, 7);
  const Eigen::Matrix3d e = EssentialEightPoint(c.bearings1, c.bearings2);
  Eigen::Matrix3d expected = EssentialFromPose(truth);
  expected /= expected.norm();
  const Eigen::Matrix3d estimated = e / e.norm();
  EXPECT_LT(std::min((estimated - expected).norm(), (estimated + expected).norm()), 1e-9);
  // Eq. (15): singular values (1, 1, 0).
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(e);
  EXPECT_NEAR(svd.singularValues()(0), 1.0, 1e-12);
  EXPECT_NEAR(svd.singularValues()(1), 1.0, 1e-12);
  EXPECT_NEAR(svd.singularValues()(2), 0.0, 1e-12);
  for (size_t i = 0; i < c.bearings1.size(); ++i) {
    EXPECT_LT(EpipolarAngularError(e, c.bearings1[i], c.bearings2[i]), 1e-9);
  }
}

TEST(Essential, EightPointConditioningHelpsInANarrowCone) {
  // Bearings within 10 degrees of the optical axis: without conditioning, eq. (14) is badly
  // scaled; with it, noise-free data are still fitted to machine precision.
  std::mt19937_64 rng(5);
  const Rigid3d truth = RandomPose(rng, Eigen::Vector3d(1, 0, 0));
  std::vector<Eigen::Vector3d> b1, b2;
  std::uniform_real_distribution<double> u(-0.17, 0.17);
  std::uniform_real_distribution<double> depth(2.0, 6.0);
  while (b1.size() < 30) {
    const Eigen::Vector3d p = depth(rng) * Eigen::Vector3d(u(rng), u(rng), 1.0);
    b1.push_back(p.normalized());
    b2.push_back((truth * p).normalized());
  }
  const Eigen::Matrix3d e = EssentialEightPoint(b1, b2);
  const std::vector<Rigid3d> candidates = DecomposeEssential(e);
  int support = 0;
  const int chosen = SelectDecomposition(candidates, b1, b2, {}, 1e-6, &support);
  // An empty index list selects nothing: SelectDecomposition has no implicit "all".
  EXPECT_EQ(chosen, -1);
  std::vector<int> all(b1.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  const int best = SelectDecomposition(candidates, b1, b2, all, 1e-6, &support);
  ASSERT_GE(best, 0);
  EXPECT_EQ(support, 30);
  EXPECT_LT(RotationDistanceRad(candidates[best].rotation, truth.rotation), 1e-8);
  EXPECT_LT(TranslationAngle(candidates[best].translation, truth.translation), 1e-8);
}

// The correct decomposition among the four of eq. (17), for motions in every direction with
// points all around the sphere: forward, backward, sideways, vertical, oblique.
TEST(Essential, ChoosesTheCorrectDecompositionForAnyMotion) {
  const std::vector<Eigen::Vector3d> directions = {{0, 0, 1}, {0, 0, -1}, {1, 0, 0},  {-1, 0, 0},
                                                   {0, 1, 0}, {0, -1, 0}, {1, 1, -1}, {-1, 2, 0.5}};
  std::mt19937_64 rng(11);
  for (size_t k = 0; k < directions.size(); ++k) {
    const Rigid3d truth = RandomPose(rng, directions[k].normalized());
    const Correspondences c = MakeCorrespondences(truth, 200, 2e-4, 0.0, 100 + k);
    std::vector<int> all(c.bearings1.size());
    for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
    const std::vector<Rigid3d> candidates =
        DecomposeEssential(EssentialEightPoint(c.bearings1, c.bearings2));
    ASSERT_EQ(candidates.size(), 4u);
    int support = 0;
    const int best = SelectDecomposition(candidates, c.bearings1, c.bearings2, all, 1e-2, &support);
    ASSERT_GE(best, 0);
    EXPECT_LT(RotationDistanceRad(candidates[best].rotation, truth.rotation), 2e-3) << k;
    EXPECT_LT(TranslationAngle(candidates[best].translation, truth.translation), 1e-2) << k;
    EXPECT_GT(support, 190) << k;
    // The other three are supported by far fewer pairs.
    for (int other = 0; other < 4; ++other) {
      if (other == best) continue;
      int other_support = 0;
      SelectDecomposition({candidates[other]}, c.bearings1, c.bearings2, all, 1e-2, &other_support);
      EXPECT_LT(other_support, support / 2) << k << " candidate " << other;
    }
  }
}

TEST(Essential, RansacFindsInliersAmongThirtyPercentOutliers) {
  std::mt19937_64 rng(21);
  const Rigid3d truth = RandomPose(rng, Eigen::Vector3d(0.2, 0.9, -0.3).normalized());
  const double noise = 2e-4;
  const Correspondences c = MakeCorrespondences(truth, 2000, noise, 0.3, 22);
  EssentialRansacOptions options;
  options.seed = 42;
  const EssentialReport report = EstimateEssentialRansac(c.bearings1, c.bearings2, options);
  ASSERT_TRUE(report.success) << report.reason;
  EXPECT_TRUE(report.reason.empty());
  int true_inliers = 0, found_true = 0, found_false = 0;
  for (size_t i = 0; i < c.is_inlier.size(); ++i) {
    true_inliers += c.is_inlier[i];
    if (report.inlier_mask[i]) (c.is_inlier[i] ? found_true : found_false)++;
  }
  // 1e-3 rad is five sigma of the noise per bearing: nearly every true inlier is kept, and a
  // random bearing falls within 1e-3 rad of a plane with probability ~1e-3.
  EXPECT_GT(found_true, 0.99 * true_inliers);
  EXPECT_LT(found_false, 10);
  EXPECT_EQ(report.num_inliers, found_true + found_false);
  EXPECT_LT(RotationDistanceRad(report.cam2_from_cam1.rotation, truth.rotation), 1e-3);
  EXPECT_LT(TranslationAngle(report.cam2_from_cam1.translation, truth.translation), 2e-3);
  EXPECT_NEAR(report.cam2_from_cam1.translation.norm(), 1.0, 1e-12);
  EXPECT_LT(report.rms_angular_error_rad, 2.0 * noise);
}

TEST(Essential, PureRotationIsFlaggedByItsParallax) {
  // Without translation every t fits: the report must not look like a confident baseline.
  std::mt19937_64 rng(51);
  const Rigid3d rotation_only = RandomPose(rng, Eigen::Vector3d::Zero());
  const Correspondences c = MakeCorrespondences(rotation_only, 500, 2e-4, 0.2, 52);
  EssentialRansacOptions options;
  const EssentialReport report = EstimateEssentialRansac(c.bearings1, c.bearings2, options);
  if (report.success) {
    EXPECT_LT(report.median_parallax_rad, 2e-3);
  } else {
    EXPECT_FALSE(report.reason.empty());
  }
  // With a translation the same scene has a clear parallax.
  const Rigid3d moving(rotation_only.rotation, Eigen::Vector3d(0.5, 0.0, 0.0));
  const Correspondences m = MakeCorrespondences(moving, 500, 2e-4, 0.2, 52);
  const EssentialReport moved = EstimateEssentialRansac(m.bearings1, m.bearings2, options);
  ASSERT_TRUE(moved.success) << moved.reason;
  EXPECT_GT(moved.median_parallax_rad, 0.05);
}

TEST(Essential, RansacIsDeterministicForASeed) {
  std::mt19937_64 rng(31);
  const Rigid3d truth = RandomPose(rng, Eigen::Vector3d(1, 0, 0));
  const Correspondences c = MakeCorrespondences(truth, 500, 3e-4, 0.3, 32);
  EssentialRansacOptions options;
  options.seed = 7;
  const EssentialReport a = EstimateEssentialRansac(c.bearings1, c.bearings2, options);
  const EssentialReport b = EstimateEssentialRansac(c.bearings1, c.bearings2, options);
  ASSERT_TRUE(a.success);
  EXPECT_EQ(a.inlier_mask, b.inlier_mask);
  EXPECT_EQ(a.num_iterations, b.num_iterations);
  EXPECT_EQ((a.E - b.E).norm(), 0.0);
  options.seed = 8;
  const EssentialReport c8 = EstimateEssentialRansac(c.bearings1, c.bearings2, options);
  ASSERT_TRUE(c8.success);
  EXPECT_LT(RotationDistanceRad(a.cam2_from_cam1.rotation, c8.cam2_from_cam1.rotation), 1e-3);
}

TEST(Essential, AngularErrorIsTheAngleToTheEpipolarPlane) {
  const Rigid3d pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 0, 0));
  const Eigen::Matrix3d e = EssentialFromPose(pose);
  // b1 along z: the epipolar plane in camera 2 is y = 0. Tilt b2 out of it by 0.01 rad.
  const Eigen::Vector3d b1(0, 0, 1);
  const Eigen::Vector3d b2(0, std::sin(0.01), std::cos(0.01));
  EXPECT_NEAR(EpipolarAngularError(e, b1, b2), 0.01, 1e-12);
  EXPECT_NEAR(EpipolarAngularError(e, b1, Eigen::Vector3d(1, 0, 0)), 0.0, 1e-15);
  // On the baseline every b2 is consistent.
  EXPECT_EQ(EpipolarAngularError(e, Eigen::Vector3d(1, 0, 0), b2), 0.0);
}

TEST(Essential, BadInputsAreReportedNotCrashes) {
  std::vector<Eigen::Vector3d> b1(20, Eigen::Vector3d(0, 0, 1)), b2(19, Eigen::Vector3d(0, 0, 1));
  EssentialRansacOptions options;
  EXPECT_THROW(EstimateEssentialRansac(b1, b2, options), InvalidArgument);
  EXPECT_THROW(EssentialEightPoint(b1, b2), InvalidArgument);
  std::vector<Eigen::Vector3d> few(5, Eigen::Vector3d(0, 0, 1));
  EXPECT_THROW(EssentialEightPoint(few, few), InvalidArgument);
  const EssentialReport too_few = EstimateEssentialRansac(few, few, options);
  EXPECT_FALSE(too_few.success);
  EXPECT_NE(too_few.reason.find("too few"), std::string::npos);
  EXPECT_EQ(too_few.inlier_mask.size(), 5u);

  // Unrelated bearings: no model explains min_inliers pairs.
  std::mt19937_64 rng(41);
  std::vector<Eigen::Vector3d> r1, r2;
  for (int i = 0; i < 300; ++i) {
    r1.push_back(RandomUnitVector(rng));
    r2.push_back(RandomUnitVector(rng));
  }
  options.max_iterations = 300;
  const EssentialReport random = EstimateEssentialRansac(r1, r2, options);
  EXPECT_FALSE(random.success);
  EXPECT_FALSE(random.reason.empty());

  // Zero bearings and invalid options are contract violations.
  r1[3] = Eigen::Vector3d::Zero();
  EXPECT_THROW(EstimateEssentialRansac(r1, r2, EssentialRansacOptions{}), InvalidArgument);
  EssentialRansacOptions bad;
  bad.max_angular_error_rad = -1;
  EXPECT_THROW(bad.Check(), InvalidArgument);
  bad = EssentialRansacOptions{};
  bad.confidence = 1.0;
  EXPECT_THROW(bad.Check(), InvalidArgument);
  bad = EssentialRansacOptions{};
  bad.min_inliers = 3;
  EXPECT_THROW(bad.Check(), InvalidArgument);
}

}  // namespace
}  // namespace omnirig
