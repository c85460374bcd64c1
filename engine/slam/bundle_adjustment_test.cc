#include "engine/slam/bundle_adjustment.h"

#include <algorithm>
#include <memory>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "engine/geometry/reprojection_cost.h"
#include "engine/slam/evaluation.h"
#include "testing/slam/sequence_accuracy.h"

namespace omnirig::slam {
namespace {

// A vertical catadioptric rig like the paper's: cam1 100 mm above cam0, both looking up
// their mirror axis (z), 1024x768 images.
StereoRig MakeRig() {
  StereoRig rig;
  for (CameraModel* camera : {&rig.cam0, &rig.cam1}) {
    camera->width = 1024;
    camera->height = 768;
    camera->intrinsics.params = {0.9, 280, 280, 512, 384, 0, -0.02, 0.001, 0, 0, 0};
  }
  rig.cam1.intrinsics.params[UnifiedIntrinsics::kU0] = 509;
  rig.cam0_from_cam1 = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitX())),
                               Eigen::Vector3d(0.002, -0.001, 0.1));
  return rig;
}

struct SyntheticScene {
  SlamMap map;
  std::vector<Rigid3d> true_rig_from_world;
  std::vector<Eigen::Vector3d> true_points;
  int num_outliers = 0;
};

// Six rig poses along x through a box of points 2-4 m away; noisy observations in both
// cameras, some gross outliers, and perturbed initial values.
SyntheticScene MakeScene(const StereoRig& rig, double noise_px, double outlier_fraction) {
  SyntheticScene scene;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  std::normal_distribution<double> noise(0, noise_px);
  for (int f = 0; f < 6; ++f) {
    const Rigid3d world_from_rig(
        Eigen::Quaterniond(Eigen::AngleAxisd(0.05 * f, Eigen::Vector3d::UnitZ())),
        Eigen::Vector3d(0.15 * f, 0.02 * f, 0));
    scene.true_rig_from_world.push_back(world_from_rig.Inverse());
    scene.map.AddFrame();
    scene.map.has_pose[f] = true;
  }
  for (int i = 0; i < 300; ++i) {
    const double angle = M_PI * u(rng), range = 3 + u(rng);
    scene.true_points.emplace_back(range * std::cos(angle), range * std::sin(angle), 1.2 * u(rng));
    Landmark landmark;
    for (int f = 0; f < 6; ++f) {
      for (int c = 0; c < 2; ++c) {
        const CameraModel& camera = c == 0 ? rig.cam0 : rig.cam1;
        const auto pixel = Project(camera.intrinsics, CamFromRig(rig, c) *
                                                          (scene.true_rig_from_world[f] *
                                                           scene.true_points.back()));
        if (!pixel) continue;
        Observation o{f, c, i, *pixel + Eigen::Vector2d(noise(rng), noise(rng))};
        if (u(rng) < 2 * outlier_fraction - 1) {
          o.pixel += Eigen::Vector2d(30 + 20 * u(rng), -25 + 10 * u(rng));
          ++scene.num_outliers;
        }
        landmark.observations.push_back(o);
      }
    }
    landmark.point_in_world = scene.true_points.back() + 0.05 * Eigen::Vector3d(u(rng), u(rng), u(rng));
    scene.map.landmarks.push_back(landmark);
  }
  for (int f = 0; f < 6; ++f) {
    const Rigid3d perturbation(
        Eigen::Quaterniond(Eigen::AngleAxisd(f == 0 ? 0 : 0.01, Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized())),
        f == 0 ? Eigen::Vector3d::Zero() : Eigen::Vector3d(0.04 * u(rng), 0.04 * u(rng), 0.04 * u(rng)));
    scene.map.rig_from_world[f] = perturbation * scene.true_rig_from_world[f];
  }
  return scene;
}

TEST(BundleAdjust, ConvergesToTruthWithNoiseAndPrunesOutliers) {
  const StereoRig rig = MakeRig();
  SyntheticScene scene = MakeScene(rig, 0.3, 0.03);
  ASSERT_GT(scene.num_outliers, 20);
  BundleAdjustmentOptions options;
  const BundleAdjustmentReport report = BundleAdjust(rig, {0, 1, 2, 3, 4, 5}, options, &scene.map);
  EXPECT_EQ(report.num_constant_poses, 1);  // the gauge
  EXPECT_EQ(report.num_free_poses, 5);
  EXPECT_GT(report.initial_rms_px, 5.0);
  EXPECT_LT(report.final_rms_px, 0.45);
  EXPECT_GE(report.num_observations_pruned, scene.num_outliers * 9 / 10);
  EXPECT_LE(report.num_observations_pruned, scene.num_outliers + 10);
  EXPECT_EQ(report.linear_solver, "DENSE_SCHUR");
  for (int f = 1; f < 6; ++f) {
    const Rigid3d& estimate = scene.map.rig_from_world[f];
    const Rigid3d& truth = scene.true_rig_from_world[f];
    EXPECT_LT((estimate.Inverse().translation - truth.Inverse().translation).norm(), 0.003)
        << "frame " << f;
    EXPECT_LT(RotationDistanceRad(estimate.rotation, truth.rotation), 2e-4) << "frame " << f;
  }
  // Depth noise grows with range squared over the 0.75 m of travel: judge the median point.
  std::vector<double> point_errors;
  for (size_t i = 0; i < scene.true_points.size(); ++i) {
    if (!scene.map.landmarks[i].valid) continue;
    point_errors.push_back((scene.map.landmarks[i].point_in_world - scene.true_points[i]).norm());
  }
  ASSERT_GT(point_errors.size(), 250u);
  std::nth_element(point_errors.begin(), point_errors.begin() + point_errors.size() / 2,
                   point_errors.end());
  EXPECT_LT(point_errors[point_errors.size() / 2], 0.015);
}

TEST(BundleAdjust, RecoversMetricScaleFromTheStereoBaseline) {
  // Scale every pose and point by 1.1: only the 100 mm baseline says the truth.
  const StereoRig rig = MakeRig();
  SyntheticScene scene = MakeScene(rig, 0.0, 0.0);
  for (int f = 0; f < 6; ++f) {
    scene.map.rig_from_world[f] = scene.true_rig_from_world[f];
    scene.map.rig_from_world[f].translation *= 1.1;
  }
  for (size_t i = 0; i < scene.true_points.size(); ++i) {
    scene.map.landmarks[i].point_in_world = 1.1 * scene.true_points[i];
  }
  BundleAdjustmentOptions options;
  options.max_iterations = 100;
  BundleAdjust(rig, {0, 1, 2, 3, 4, 5}, options, &scene.map);
  const double true_length = scene.true_rig_from_world[5].Inverse().translation.norm();
  const double length = scene.map.rig_from_world[5].Inverse().translation.norm();
  EXPECT_NEAR(length / true_length, 1.0, 1e-4);
}

TEST(BundleAdjust, ReportsIterationsAndAbortsWhenCancelled) {
  const StereoRig rig = MakeRig();
  BundleAdjustmentOptions options;
  options.max_iterations = 100;
  {
    SyntheticScene scene = MakeScene(rig, 0.3, 0.0);
    std::vector<double> fractions;
    const ProgressSink progress{[&](double fraction, const std::string& stage, const std::string&) {
                                  EXPECT_EQ(stage, "bundle_adjustment");
                                  fractions.push_back(fraction);
                                },
                                nullptr};
    const BundleAdjustmentReport report =
        BundleAdjust(rig, {0, 1, 2, 3, 4, 5}, options, &scene.map, progress);
    EXPECT_GE(static_cast<int>(fractions.size()), report.solver.num_iterations);
    EXPECT_GT(fractions.size(), 1u);
    EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  }
  // Cancelled after the second iteration: the solver stops there instead of converging.
  SyntheticScene scene = MakeScene(rig, 0.3, 0.0);
  const std::vector<Rigid3d> before = scene.map.rig_from_world;
  int iterations_seen = 0;
  const ProgressSink progress{[&](double, const std::string&, const std::string&) {
                                ++iterations_seen;
                              },
                              [&] { return iterations_seen >= 2; }};
  EXPECT_THROW(BundleAdjust(rig, {0, 1, 2, 3, 4, 5}, options, &scene.map, progress), Cancelled);
  EXPECT_EQ(iterations_seen, 2);
  for (int f = 0; f < 6; ++f) {
    EXPECT_EQ(scene.map.rig_from_world[f].translation, before[f].translation) << "frame " << f;
  }
}

TEST(RefineRigPose, RecoversAPerturbedPoseAndFlagsOutliers) {
  const StereoRig rig = MakeRig();
  const SyntheticScene scene = MakeScene(rig, 0.3, 0.05);
  std::vector<Observation> observations;
  std::vector<Eigen::Vector3d> points;
  for (size_t i = 0; i < scene.true_points.size(); ++i) {
    for (const Observation& o : scene.map.landmarks[i].observations) {
      if (o.frame != 3) continue;
      observations.push_back(o);
      points.push_back(scene.true_points[i]);
    }
  }
  std::vector<bool> inliers;
  const Rigid3d refined = RefineRigPose(rig, scene.map.rig_from_world[3], observations, points,
                                        BundleAdjustmentOptions(), &inliers);
  const Rigid3d& truth = scene.true_rig_from_world[3];
  EXPECT_LT((refined.Inverse().translation - truth.Inverse().translation).norm(), 0.003);
  EXPECT_LT(RotationDistanceRad(refined.rotation, truth.rotation), 3e-4);
  const int num_inliers = static_cast<int>(std::count(inliers.begin(), inliers.end(), true));
  EXPECT_LT(num_inliers, static_cast<int>(observations.size()));
  EXPECT_GT(num_inliers, static_cast<int>(observations.size()) * 8 / 10);
}

TEST(BundleAdjustmentOptions, RejectsNonsense) {
  BundleAdjustmentOptions options;
  options.huber_scale_px = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

// The residual over the calibration blocks equals the fixed-calibration one at the same values
// (the Jacobians of both: engine/geometry/reprojection_cost_test.cc).
TEST(ReprojectionCost, LandmarkWithCalibrationMatchesTheFixedCalibration) {
  const StereoRig rig = MakeRig();
  std::array<double, 7> pose =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())),
              Eigen::Vector3d(0.2, -0.1, 0.05))
          .ToParams();
  std::array<double, 3> point = {2.0, -1.0, 0.4};
  Eigen::Vector4d rotation = rig.cam0_from_cam1.rotation.coeffs();
  Eigen::Vector3d translation = rig.cam0_from_cam1.translation;
  const Eigen::Vector2d observed(600, 300);
  for (int camera = 0; camera < 2; ++camera) {
    const CameraModel& model = camera == 0 ? rig.cam0 : rig.cam1;
    std::array<double, UnifiedIntrinsics::kNumParams> intrinsics = model.intrinsics.params;
    const std::unique_ptr<ceres::CostFunction> fixed(
        ReprojectionCost::Landmark(observed, CamFromRig(rig, camera), model.intrinsics));
    const double* fixed_params[2] = {pose.data(), point.data()};
    double expected[2], actual[2];
    ASSERT_TRUE(fixed->Evaluate(fixed_params, expected, nullptr));
    const std::unique_ptr<ceres::CostFunction> free(
        ReprojectionCost::LandmarkWithCalibration(camera, observed));
    const double* cam0_params[3] = {pose.data(), point.data(), intrinsics.data()};
    const double* cam1_params[5] = {pose.data(), point.data(), rotation.data(),
                                    translation.data(), intrinsics.data()};
    ASSERT_TRUE(free->Evaluate(camera == 0 ? cam0_params : cam1_params, actual, nullptr));
    EXPECT_NEAR(actual[0], expected[0], 1e-9);
    EXPECT_NEAR(actual[1], expected[1], 1e-9);
  }
}

TEST(BundleAdjustWithCalibration, RefinesAPerturbedCalibrationTowardsTheTruth) {
  const StereoRig truth = MakeRig();
  const std::vector<int> frames = {0, 1, 2, 3, 4, 5};
  // Reference: the same perturbed start with the calibration held fixed.
  SyntheticScene fixed_scene = MakeScene(truth, 0.3, 0.0);
  const BundleAdjustmentReport fixed_report = BundleAdjust(
      PerturbedCalibration(truth), frames, BundleAdjustmentOptions(), &fixed_scene.map);

  SyntheticScene scene = MakeScene(truth, 0.3, 0.0);
  StereoRig rig = PerturbedCalibration(truth);
  CalibrationRefinementOptions refinement;
  refinement.refine = CalibrationRefinement::kAll;
  CalibrationRefinementReport calibration;
  BundleAdjustmentOptions options;
  options.max_iterations = 100;
  const BundleAdjustmentReport report =
      BundleAdjustWithCalibration(refinement, frames, options, &rig, &scene.map, &calibration);
  ASSERT_TRUE(calibration.applied) << calibration.reason;
  EXPECT_EQ(calibration.free_parameters.size(), 9u);  // 4 per camera + the rig's rotation
  for (int c = 0; c < 2; ++c) {
    const UnifiedIntrinsics& t = c == 0 ? truth.cam0.intrinsics : truth.cam1.intrinsics;
    const UnifiedIntrinsics& before = c == 0 ? calibration.before.cam0.intrinsics
                                             : calibration.before.cam1.intrinsics;
    const UnifiedIntrinsics& after = c == 0 ? rig.cam0.intrinsics : rig.cam1.intrinsics;
    const double error_before = CalibrationPixelRms(t, before, 100, 380);
    const double error_after = CalibrationPixelRms(t, after, 100, 380);
    EXPECT_GT(error_before, 1.0) << "cam" << c;
    // Measured 2.28 -> 0.58 and 0.60 px: the scene's points span +-22 degrees of elevation,
    // over which the focal length trades against the points' depths; the rest of the mirror
    // is extrapolated.
    EXPECT_LT(error_after, 0.3 * error_before) << "cam" << c;
    EXPECT_EQ(after.xi(), t.xi()) << "cam" << c << ": xi is held";
  }
  EXPECT_EQ(rig.cam0_from_cam1.translation, truth.cam0_from_cam1.translation);  // held
  const double rotation_before = RotationDistanceRad(calibration.before.cam0_from_cam1.rotation,
                                                     truth.cam0_from_cam1.rotation);
  const double rotation_after =
      RotationDistanceRad(rig.cam0_from_cam1.rotation, truth.cam0_from_cam1.rotation);
  EXPECT_LT(rotation_after, 0.1 * rotation_before);  // measured 3.5 -> 0.08 mrad
  EXPECT_LT(report.final_rms_px, 0.7 * fixed_report.final_rms_px);
  EXPECT_LT(report.final_rms_px, 0.45);
  for (int f = 1; f < 6; ++f) {
    const double error = (scene.map.rig_from_world[f].Inverse().translation -
                          scene.true_rig_from_world[f].Inverse().translation).norm();
    const double fixed_error = (fixed_scene.map.rig_from_world[f].Inverse().translation -
                                scene.true_rig_from_world[f].Inverse().translation).norm();
    EXPECT_LT(error, std::max(fixed_error, 0.003)) << "frame " << f;
  }
}

TEST(BundleAdjustWithCalibration, RefusesTooSmallAProblemAndKeepsTheCalibration) {
  const StereoRig truth = MakeRig();
  SyntheticScene scene = MakeScene(truth, 0.3, 0.0);
  StereoRig rig = PerturbedCalibration(truth);
  const StereoRig given = rig;
  CalibrationRefinementOptions refinement;
  refinement.refine = CalibrationRefinement::kIntrinsics;
  refinement.min_frames = 10;  // the scene has 6
  CalibrationRefinementReport calibration;
  const BundleAdjustmentReport report = BundleAdjustWithCalibration(
      refinement, {0, 1, 2, 3, 4, 5}, BundleAdjustmentOptions(), &rig, &scene.map, &calibration);
  EXPECT_FALSE(calibration.applied);
  EXPECT_NE(calibration.reason.find("too few rig positions"), std::string::npos)
      << calibration.reason;
  EXPECT_EQ(rig.cam0.intrinsics.params, given.cam0.intrinsics.params);
  EXPECT_EQ(rig.cam1.intrinsics.params, given.cam1.intrinsics.params);
  EXPECT_GT(report.num_free_poses, 0);  // the poses and points were still adjusted

  refinement.min_frames = 5;
  refinement.min_observations_per_camera = 100000;
  SyntheticScene again = MakeScene(truth, 0.3, 0.0);
  BundleAdjustWithCalibration(refinement, {0, 1, 2, 3, 4, 5}, BundleAdjustmentOptions(), &rig,
                              &again.map, &calibration);
  EXPECT_FALSE(calibration.applied);
  EXPECT_NE(calibration.reason.find("too few observations in cam0"), std::string::npos)
      << calibration.reason;
}

TEST(CalibrationRefinementOptions, RejectsAllIntrinsicsFixed) {
  CalibrationRefinementOptions options;
  options.refine = CalibrationRefinement::kIntrinsics;
  options.fixed_intrinsics.fill(true);
  EXPECT_THROW(options.Check(), InvalidArgument);
  options.refine = CalibrationRefinement::kRig;
  EXPECT_NO_THROW(options.Check());
}

}  // namespace
}  // namespace omnirig::slam
