// The relative pose's statistics over noisy trials (label integration: a dozen estimates take
// about a minute under the sanitizers).

#include <cmath>

#include <gtest/gtest.h>

#include "engine/rig/relative_pose.h"
#include "testing/rig/relpose_test_scene.h"

namespace omnirig {
namespace {

using namespace relpose_test;  // NOLINT: the shared test scenes

// Across noisy trials, the scatter of the baseline error matches the reported standard
// deviation, and the refined rig beats the per-pair average.
TEST(RelativePose, NoiseGivesConsistentStandardDeviation) {
  const double noise_px = 0.3;
  const int num_trials = 12;
  double sum_sq_error = 0.0, sum_sq_std = 0.0, sum_sq_average_error = 0.0;
  for (int trial = 0; trial < num_trials; ++trial) {
    const Scene scene = MakeScene(noise_px, 10, 100 + trial);
    const RelativePoseReport report = Estimate(scene);
    ASSERT_TRUE(report.success) << report.message;
    // rms_px is the RMS of the Euclidean corner error: sigma * sqrt(2) for noise of sigma per
    // axis.
    EXPECT_NEAR(report.rms_px, noise_px * std::sqrt(2.0), 0.1 * noise_px);
    const double truth = scene.rig.cam0_from_cam1.translation.norm();
    sum_sq_error += std::pow(report.baseline_m - truth, 2);
    sum_sq_std += std::pow(report.baseline_std_m, 2);
    sum_sq_average_error +=
        (report.averaged_cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation)
            .squaredNorm();
    EXPECT_GT(report.rotation_std_deg, 0.0);
    EXPECT_LT(RotationErrorDeg(report.rig.cam0_from_cam1, scene.rig.cam0_from_cam1),
              5.0 * report.rotation_std_deg);
  }
  const double empirical = std::sqrt(sum_sq_error / num_trials);
  const double predicted = std::sqrt(sum_sq_std / num_trials);
  EXPECT_GT(predicted, 1e-6);
  EXPECT_LT(predicted, 1e-3);
  EXPECT_GT(empirical / predicted, 0.5);
  EXPECT_LT(empirical / predicted, 2.0);
  EXPECT_LT(empirical, std::sqrt(sum_sq_average_error / num_trials));
}

}  // namespace
}  // namespace omnirig
