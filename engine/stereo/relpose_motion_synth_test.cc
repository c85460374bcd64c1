// The board motion model (relpose_motion.h) against eq. 20 alone on seeded synthetic rigs like
// the real fisheye pairs (relpose_motion_scene.h), with and without the board moving between
// the two exposures (label integration: about 120 rig estimates). The decision rule of issue 4,
// fixed before the comparison was run: the model may be the default only if, with motion, it
// does not raise the RMS rig error and makes the reported baseline std honest (|error| < 2 std
// in about 95 % of the seeds), and, without motion, it changes nothing. Also eq. 20's
// cluster-robust std over pairs (relpose_refine.h), honest in both cases.

#include <cstdio>

#include <gtest/gtest.h>

#include "engine/stereo/relpose_motion_scene.h"

namespace omnirig {
namespace {

using namespace relpose_test;  // NOLINT: the shared test scenes

void Print(const char* name, const MotionComparison& c) {
  std::printf("%s: %d seeds (%d failed), model used in %d (mean sigma %.3f deg, %.3f mm)\n", name,
              c.num_seeds, c.failures, c.motion_used, c.mean_motion_rotation_std_deg,
              c.mean_motion_translation_std_m * 1e3);
  const char* labels[2] = {"eq. 20 alone", "board motion"};
  for (int m = 0; m < 2; ++m) {
    std::printf(
        "  %-13s RMS baseline error %.4f mm, RMS translation error %.4f mm, RMS rotation error "
        "%.5f deg, mean reported baseline std %.4f mm, |error| < 2 std in %d/%d\n",
        labels[m], c.rms_baseline_error_m[m] * 1e3, c.rms_translation_error_m[m] * 1e3,
        c.rms_rotation_error_deg[m], c.mean_baseline_std_m[m] * 1e3, c.covered[m], c.num_seeds);
  }
  for (int m = 0; m < 2; ++m) {
    std::printf("  %-13s cluster-robust std: mean %.4f mm, |error| < 2 std in %d/%d\n", labels[m],
                c.mean_baseline_std_robust_m[m] * 1e3, c.covered_robust[m], c.num_seeds);
  }
  std::printf("  identical to eq. 20 alone in %d/%d seeds\n", c.identical, c.num_seeds);
}

TEST(BoardMotionSynthetic, WithMotionTheStdIsHonestAndTheErrorNoLarger) {
  MotionSceneOptions scene;
  scene.rotation_std_deg = 0.3;
  scene.translation_std_m = 0.0005;
  const MotionComparison c = CompareMotionModel(scene, 30, 4000);
  Print("board moved 0.3 deg, 0.5 mm per axis", c);
  ASSERT_EQ(c.failures, 0);
  EXPECT_GE(c.motion_used, c.num_seeds - 1);
  EXPECT_LE(c.rms_baseline_error_m[1], 1.05 * c.rms_baseline_error_m[0]);
  EXPECT_LE(c.rms_rotation_error_deg[1], 1.05 * c.rms_rotation_error_deg[0]);
  EXPECT_LE(c.rms_translation_error_m[1], c.rms_translation_error_m[0]);
  // 95 % nominal over 30 seeds: 24 or fewer has probability about 1 %.
  EXPECT_GE(c.covered[1], 25);
  EXPECT_LT(c.covered[0], c.covered[1]);
  // Eq. 20's own covariance ignores the motion; its cluster-robust std over pairs does not.
  EXPECT_GE(c.covered_robust[0], 25);
  EXPECT_GT(c.mean_baseline_std_robust_m[0], 2.0 * c.mean_baseline_std_m[0]);
}

TEST(BoardMotionSynthetic, WithoutMotionNothingChanges) {
  MotionSceneOptions scene;
  const MotionComparison c = CompareMotionModel(scene, 30, 5000);
  Print("board still", c);
  ASSERT_EQ(c.failures, 0);
  // alpha = 1 %: 2 or more of 30 rigs using the model has probability under 4 %.
  EXPECT_LE(c.motion_used, 1);
  EXPECT_EQ(c.identical, c.num_seeds - c.motion_used);
  // Without motion the cluster-robust std estimates the same spread as the covariance.
  EXPECT_GE(c.covered_robust[0], 25);
  EXPECT_NEAR(c.mean_baseline_std_robust_m[0] / c.mean_baseline_std_m[0], 1.0, 0.25);
}

}  // namespace
}  // namespace omnirig
