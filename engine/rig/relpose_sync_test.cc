#include "engine/rig/relpose_sync.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "testing/rig/relpose_test_scene.h"

namespace omnirig {
namespace {

using namespace relpose_test;  // NOLINT: the shared test scenes

// A rig like the real fisheye pairs': 9 x 6 corners, 0.12 px of noise per coordinate (their
// mono calibrations' 0.17-0.19 px RMS of the Euclidean error), 20 pairs.
constexpr double kNoisePx = 0.12;
constexpr int kNumPairs = 20;

Scene RealLikeScene(unsigned seed) { return MakeScene(kNoisePx, kNumPairs, seed, 9, 6); }

TEST(ChiSquare, SurvivalAndQuantilesMatchTables) {
  EXPECT_NEAR(ChiSquareSurvival(12.5916, 6), 0.05, 1e-5);
  EXPECT_NEAR(ChiSquareSurvival(5.99146, 2), 0.05, 1e-5);
  EXPECT_DOUBLE_EQ(ChiSquareSurvival(0.0, 6), 1.0);
  EXPECT_NEAR(ChiSquareUpperQuantile(0.01, 6), 16.8119, 1e-4);
  EXPECT_NEAR(ChiSquareUpperQuantile(0.001, 6), 22.4577, 1e-4);
  EXPECT_NEAR(ChiSquareUpperQuantile(0.5, 6), 5.34812, 1e-5);  // the median
  EXPECT_NEAR(ChiSquareUpperQuantile(0.5, 100), 99.3341, 1e-3);
  EXPECT_THROW(ChiSquareSurvival(1.0, 5), InvalidArgument);
  EXPECT_THROW(ChiSquareUpperQuantile(0.0, 6), InvalidArgument);
}

// 6 F(6, n) against F tables (F_0.05(6, 20) = 2.599, F_0.01(6, 20) = 3.871, F_0.05(6, 120) =
// 2.175), and its limit chi^2_6 for large n.
TEST(ScaledF, SurvivalAndQuantilesMatchTables) {
  EXPECT_NEAR(ScaledFSurvival(6 * 2.599, 6, 20), 0.05, 1e-4);
  EXPECT_NEAR(ScaledFSurvival(6 * 3.871, 6, 20), 0.01, 1e-5);
  EXPECT_NEAR(ScaledFSurvival(6 * 2.175, 6, 120), 0.05, 1e-4);
  EXPECT_NEAR(ScaledFSurvival(16.8119, 6, 1e7), 0.01, 1e-6);
  EXPECT_NEAR(ScaledFUpperQuantile(0.01, 6, 20), 6 * 3.871, 1e-2);
  EXPECT_DOUBLE_EQ(ScaledFSurvival(0.0, 6, 90), 1.0);
  EXPECT_THROW(ScaledFSurvival(1.0, 5, 90), InvalidArgument);
  EXPECT_THROW(ScaledFSurvival(1.0, 6, 0.0), InvalidArgument);
}

TEST(SyncTestOptions, InvalidValuesThrow) {
  SyncTestOptions options;
  options.Check();
  options.false_alarm_rate = 1.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = SyncTestOptions();
  options.min_corner_noise_px = 0.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = SyncTestOptions();
  options.max_rounds = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

// Simultaneous pairs: the noise comes out right, no pair is flagged, and the statistic has the
// mean of chi^2_6 (a little below 6: the rig was fitted with the same pairs).
TEST(PairSynchronisation, SimultaneousPairsFollowChiSquare) {
  double sum = 0.0;
  int count = 0;
  for (unsigned seed = 0; seed < 3; ++seed) {
    const Scene scene = RealLikeScene(300 + seed);
    const RelativePoseReport report = Estimate(scene);
    ASSERT_TRUE(report.success) << report.message;
    EXPECT_EQ(report.num_pairs_used, kNumPairs);
    EXPECT_EQ(report.sync_rounds, 0);
    ASSERT_TRUE(report.sync_test.run);
    EXPECT_EQ(report.sync_test.num_flagged, 0);
    for (double noise : report.sync_test.corner_noise_px)
      EXPECT_NEAR(noise, kNoisePx, 0.1 * kNoisePx);
    EXPECT_NEAR(report.sync_test.limit, ChiSquareUpperQuantile(0.01 / kNumPairs, 6), 1e-9);
    for (const RelativePosePairReport& pair : report.pairs) {
      ASSERT_GE(pair.sync_statistic, 0.0) << pair.name;
      sum += pair.sync_statistic;
      ++count;
    }
  }
  EXPECT_GT(sum / count, 4.0);
  EXPECT_LT(sum / count, 7.0);
}

// Three boards moved by 2 to 3 mm between the two cameras' shots: exactly those are left out,
// with the reason, and the rig is closer to the truth than with them kept.
TEST(PairSynchronisation, BoardsMovedBetweenShotsAreLeftOut) {
  Scene scene = RealLikeScene(7);
  const int moved[3] = {2, 8, 13};
  const Eigen::Vector3d shifts_m[3] = {Eigen::Vector3d(0.002, 0.0, 0.0),
                                       Eigen::Vector3d(0.0, -0.0015, 0.0015),
                                       Eigen::Vector3d(0.001, 0.002, -0.002)};
  for (int k = 0; k < 3; ++k) MoveBoardBeforeCam1(moved[k], shifts_m[k], kNoisePx, 40 + k, &scene);
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  for (int i = 0; i < kNumPairs; ++i) {
    const bool is_moved = i == moved[0] || i == moved[1] || i == moved[2];
    EXPECT_EQ(report.pairs[i].used, !is_moved) << i << ": " << report.pairs[i].reason;
    if (!is_moved) continue;
    EXPECT_NE(report.pairs[i].reason.find("exposures not simultaneous?"), std::string::npos)
        << report.pairs[i].reason;
    EXPECT_NE(report.pairs[i].reason.find("mm"), std::string::npos);
    EXPECT_GT(report.pairs[i].sync_statistic, report.sync_test.limit);
    EXPECT_GT(report.pairs[i].board_offset_m, 0.0);
  }
  EXPECT_GE(report.sync_rounds, 1);
  RelativePoseOptions kept_options;
  kept_options.sync_test.false_alarm_rate = 0.0;
  const RelativePoseReport kept = Estimate(scene, kept_options);
  ASSERT_TRUE(kept.success) << kept.message;
  EXPECT_EQ(kept.num_pairs_used, kNumPairs);
  const Rigid3d& truth = scene.rig.cam0_from_cam1;
  const double error = (report.rig.cam0_from_cam1.translation - truth.translation).norm();
  const double kept_error = (kept.rig.cam0_from_cam1.translation - truth.translation).norm();
  EXPECT_LT(error, kept_error);
  EXPECT_LT(RotationErrorDeg(report.rig.cam0_from_cam1, truth),
            RotationErrorDeg(kept.rig.cam0_from_cam1, truth));
  EXPECT_LT(report.rms_px, kept.rms_px);
}

}  // namespace
}  // namespace omnirig
