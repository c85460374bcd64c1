// The synchronisation test's false-alarm rate and power over many seeded synthetic rigs (label
// integration: about 150 rig estimates). The rig is like the real fisheye pairs': 9 x 6 corners,
// 0.12 px of noise per coordinate, 20 pairs, boards 0.6-0.9 m away.

#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>

#include "engine/rig/relative_pose.h"
#include "testing/rig/relpose_test_scene.h"

namespace omnirig {
namespace {

using namespace relpose_test;  // NOLINT: the shared test scenes

constexpr double kNoisePx = 0.12;
constexpr int kNumPairs = 20;

Eigen::Vector3d RandomDirection(std::mt19937* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  return Eigen::Vector3d(normal(*rng), normal(*rng), normal(*rng)).normalized();
}

// Sets of simultaneous pairs: the test is built to lose a pair in at most 1 % of them.
TEST(PairSynchronisationPower, FalseAlarmsStayRare) {
  const int num_seeds = 100;
  int seeds_with_false_alarm = 0;
  for (int seed = 0; seed < num_seeds; ++seed) {
    const Scene scene = MakeScene(kNoisePx, kNumPairs, 1000 + seed, 9, 6);
    const RelativePoseReport report = Estimate(scene);
    ASSERT_TRUE(report.success) << report.message;
    seeds_with_false_alarm += report.num_pairs_used < kNumPairs ? 1 : 0;
  }
  std::printf("simultaneous pairs: %d of %d rigs lost a pair\n", seeds_with_false_alarm, num_seeds);
  // Expected at most 1 at the nominal 1 %; 4 or more would have probability under 2 %.
  EXPECT_LE(seeds_with_false_alarm, 3);
}

// Three pairs per rig with the board moved by 1, 2 and 3 mm (random directions) between the
// two shots: the 2 and 3 mm moves are always flagged, the 1 mm move (near the noise: the two
// own fits disagree by about 1 mm along the line of sight from noise alone) in most rigs, the
// other pairs almost never; leaving them out brings the rig closer to the truth.
TEST(PairSynchronisationPower, MovedBoardsAreFoundAndTheRigImproves) {
  const int num_seeds = 20;
  const int moved[3] = {3, 9, 15};
  int found[3] = {0, 0, 0}, false_alarms = 0, closer = 0;
  double sum_sq_error = 0.0, sum_sq_kept_error = 0.0;
  for (int seed = 0; seed < num_seeds; ++seed) {
    Scene scene = MakeScene(kNoisePx, kNumPairs, 500 + seed, 9, 6);
    std::mt19937 rng(900 + seed);
    for (int k = 0; k < 3; ++k) {
      MoveBoardBeforeCam1(moved[k], 0.001 * (k + 1) * RandomDirection(&rng), kNoisePx, 77 + seed,
                          &scene);
    }
    const RelativePoseReport report = Estimate(scene);
    RelativePoseOptions kept_options;
    kept_options.sync_test.false_alarm_rate = 0.0;
    const RelativePoseReport kept = Estimate(scene, kept_options);
    ASSERT_TRUE(report.success && kept.success) << report.message << kept.message;
    for (int i = 0; i < kNumPairs; ++i) {
      const int k = i == moved[0] ? 0 : i == moved[1] ? 1 : i == moved[2] ? 2 : -1;
      if (k >= 0) found[k] += report.pairs[i].used ? 0 : 1;
      if (k < 0) false_alarms += report.pairs[i].used ? 0 : 1;
    }
    const Eigen::Vector3d& truth = scene.rig.cam0_from_cam1.translation;
    const double error = (report.rig.cam0_from_cam1.translation - truth).norm();
    const double kept_error = (kept.rig.cam0_from_cam1.translation - truth).norm();
    sum_sq_error += error * error;
    sum_sq_kept_error += kept_error * kept_error;
    closer += error < kept_error ? 1 : 0;
  }
  const double rms_error_mm = 1e3 * std::sqrt(sum_sq_error / num_seeds);
  const double rms_kept_error_mm = 1e3 * std::sqrt(sum_sq_kept_error / num_seeds);
  std::printf(
      "moved boards found: 1 mm %d/%d, 2 mm %d/%d, 3 mm %d/%d; simultaneous pairs flagged %d/%d; "
      "rig translation error (RMS) %.4f mm, %.4f mm with them kept; closer in %d/%d\n",
      found[0], num_seeds, found[1], num_seeds, found[2], num_seeds, false_alarms,
      num_seeds * (kNumPairs - 3), rms_error_mm, rms_kept_error_mm, closer, num_seeds);
  EXPECT_EQ(found[2], num_seeds);
  EXPECT_EQ(found[1], num_seeds);
  EXPECT_GE(found[0], num_seeds * 8 / 10);
  EXPECT_LE(false_alarms, 2);
  EXPECT_LT(rms_error_mm, 0.5 * rms_kept_error_mm);
  EXPECT_GE(closer, num_seeds * 3 / 4);
}

}  // namespace
}  // namespace omnirig
