#include "engine/rig/relpose_model_select.h"

#include <algorithm>
#include <string>

#include <gtest/gtest.h>

#include "testing/rig/relpose_test_scene.h"

namespace omnirig {
namespace {

using namespace relpose_test;  // NOLINT: the shared test scenes

constexpr int kFixed = 0, kTangentialFixed = 1, kFree = 2;  // StandardRigIntrinsicsModels order

// The three standard candidates, each starting from the given cameras; the tangential-fixed
// one from them with k3 = k4 = 0 (as its own calibrations would start).
std::vector<RigModelCandidate> Candidates(const CameraModel& cam0, const CameraModel& cam1) {
  std::vector<RigModelCandidate> candidates;
  for (const RigIntrinsicsModel& model : StandardRigIntrinsicsModels(DefaultFixedIntrinsics())) {
    RigModelCandidate candidate{model, cam0, cam1};
    if (model.calibration_fixed[UnifiedIntrinsics::kK3]) {
      for (CameraModel* camera : {&candidate.cam0, &candidate.cam1}) {
        camera->intrinsics.params[UnifiedIntrinsics::kK3] = 0.0;
        camera->intrinsics.params[UnifiedIntrinsics::kK4] = 0.0;
      }
    }
    candidates.push_back(candidate);
  }
  return candidates;
}

TEST(RigIntrinsicsModels, StandardCandidatesAreOrderedByFreedom) {
  const auto models = StandardRigIntrinsicsModels(DefaultFixedIntrinsics());
  ASSERT_EQ(models.size(), 3u);
  EXPECT_EQ(models[kFixed].name, "fixed");
  EXPECT_EQ(models[kTangentialFixed].name, "tangential_fixed");
  EXPECT_EQ(models[kFree].name, "free");
  // Both cameras: 11 parameters less skew and k5 (and k3, k4).
  EXPECT_EQ(models[kFixed].NumFreeIntrinsics(), 0);
  EXPECT_EQ(models[kTangentialFixed].NumFreeIntrinsics(), 14);
  EXPECT_EQ(models[kFree].NumFreeIntrinsics(), 18);
  EXPECT_FALSE(models[kFree].calibration_fixed[UnifiedIntrinsics::kK3]);
  EXPECT_TRUE(models[kTangentialFixed].joint_fixed[UnifiedIntrinsics::kK4]);
  // One camera's tangential terms: between the two in freedom.
  const auto per_camera = PerCameraTangentialModels(DefaultFixedIntrinsics());
  ASSERT_EQ(per_camera.size(), 2u);
  for (int camera = 0; camera < 2; ++camera) {
    const RigIntrinsicsModel& model = per_camera[camera];
    EXPECT_EQ(model.name, "tangential_free_cam" + std::to_string(camera));
    EXPECT_EQ(model.NumFreeIntrinsics(), 16);
    EXPECT_FALSE(model.JointFixed(camera)[UnifiedIntrinsics::kK3]);
    EXPECT_TRUE(model.JointFixed(1 - camera)[UnifiedIntrinsics::kK3]);
    EXPECT_TRUE(model.CalibrationFixed(1 - camera)[UnifiedIntrinsics::kK4]);
  }
  // The job's "auto" candidates: all five, simplest first; four when k3, k4 are fixed anyway.
  const auto all = AutoRigIntrinsicsModels(DefaultFixedIntrinsics());
  ASSERT_EQ(all.size(), 5u);
  for (size_t k = 1; k < all.size(); ++k) {
    EXPECT_LE(all[k - 1].NumFreeIntrinsics(), all[k].NumFreeIntrinsics()) << all[k].name;
  }
  EXPECT_EQ(all.back().name, "free");
  auto no_tangential = DefaultFixedIntrinsics();
  no_tangential[UnifiedIntrinsics::kK3] = no_tangential[UnifiedIntrinsics::kK4] = true;
  EXPECT_EQ(AutoRigIntrinsicsModels(no_tangential).size(), 2u);  // fixed, free
}

// With the true cameras the simplest model predicts held-out pairs as well as any: the rule
// keeps it rather than the freer models' slightly lower fit RMS.
TEST(RigModelSelection, TrueCamerasKeepTheSimplestModel) {
  const Scene scene = MakeScene(0.2, 10, 41);
  const RigModelSelection selection = SelectRigIntrinsicsModel(
      scene.board, scene.pairs, Candidates(scene.rig.cam0, scene.rig.cam1), {});
  ASSERT_EQ(selection.candidates.size(), 3u);
  EXPECT_EQ(selection.held_out.size(), 10u);
  for (const RigModelScore& score : selection.candidates) {
    ASSERT_TRUE(score.fit.success) << score.name << ": " << score.fit.message;
    EXPECT_EQ(score.fold_rms_px.size(), 10u);
    // Prediction from the other camera is worse than the fit, never better.
    EXPECT_GT(score.cv_rms_px, score.fit.rms_px) << score.name;
  }
  EXPECT_LT(selection.candidates[kFree].fit.rms_px, selection.candidates[kFixed].fit.rms_px);
  EXPECT_EQ(selection.chosen, kFixed) << selection.rule;
  EXPECT_EQ(selection.candidates[selection.lowest_error].cv_excess_mse_px2, 0.0);
  EXPECT_NE(selection.rule.find("fixed"), std::string::npos);
}

// Cameras calibrated badly alone (principal point 2 px off, focal length 0.5 % off): the rig
// that keeps them predicts the other camera poorly, and the choice moves to a refining model.
TEST(RigModelSelection, WrongCamerasAreRefined) {
  const Scene scene = MakeScene(0.2, 10, 43);
  CameraModel cam0 = scene.rig.cam0, cam1 = scene.rig.cam1;
  cam0.intrinsics.u0() += 2.0;
  cam1.intrinsics.gamma_u() *= 1.005;
  cam1.intrinsics.gamma_v() *= 1.005;
  const RigModelSelection selection =
      SelectRigIntrinsicsModel(scene.board, scene.pairs, Candidates(cam0, cam1), {});
  ASSERT_GE(selection.chosen, 0);
  EXPECT_NE(selection.chosen, kFixed) << selection.rule;
  EXPECT_NE(selection.lowest_error, kFixed);
  const RigModelScore& fixed = selection.candidates[kFixed];
  EXPECT_GT(fixed.cv_excess_mse_px2, 3.0 * fixed.cv_excess_se_px2);
  const RigModelScore& chosen = selection.candidates[selection.chosen];
  EXPECT_LT(std::abs(chosen.fit.baseline_m - scene.rig.cam0_from_cam1.translation.norm()),
            std::abs(fixed.fit.baseline_m - scene.rig.cam0_from_cam1.translation.norm()));
}

// Lenses whose tangential terms are real (k3, k4 ten times the scene's): the model that
// zeroes them predicts worse, so the free model is chosen.
TEST(RigModelSelection, RealTangentialTermsAreKept) {
  Scene scene = MakeScene(0.0, 10, 47);
  for (CameraModel* camera : {&scene.rig.cam0, &scene.rig.cam1}) {
    camera->intrinsics.params[UnifiedIntrinsics::kK3] = 0.004;
    camera->intrinsics.params[UnifiedIntrinsics::kK4] = -0.003;
  }
  ProjectPairs(0.2, 10, 47, &scene);
  CameraModel cam0 = scene.rig.cam0, cam1 = scene.rig.cam1;
  cam0.intrinsics.u0() += 2.0;  // the fixed model must not win either
  const RigModelSelection selection =
      SelectRigIntrinsicsModel(scene.board, scene.pairs, Candidates(cam0, cam1), {});
  ASSERT_GE(selection.chosen, 0);
  EXPECT_EQ(selection.chosen, kFree) << selection.rule;
  EXPECT_GT(selection.candidates[kTangentialFixed].cv_rms_px,
            selection.candidates[kFree].cv_rms_px);
}

// The job's threads fit candidates and folds side by side: every number is the same as on one
// thread, and the progress sink sees one call at a time, its fractions never going back.
TEST(RigModelSelection, ThreadsDoNotChangeTheResult) {
  const Scene scene = MakeScene(0.2, 10, 43);
  CameraModel cam0 = scene.rig.cam0;
  cam0.intrinsics.u0() += 2.0;
  const std::vector<RigModelCandidate> candidates = Candidates(cam0, scene.rig.cam1);
  const RigModelSelection serial = SelectRigIntrinsicsModel(scene.board, scene.pairs, candidates, {});
  RelativePoseOptions options;
  options.num_threads = 3;
  int calls_inside = 0, max_inside = 0;
  double last_fraction = 0.0;
  bool monotonic = true;
  ProgressSink progress;
  progress.report = [&](double fraction, const std::string&, const std::string&) {
    max_inside = std::max(max_inside, ++calls_inside);
    monotonic = monotonic && fraction >= last_fraction;
    last_fraction = fraction;
    --calls_inside;
  };
  const RigModelSelection parallel =
      SelectRigIntrinsicsModel(scene.board, scene.pairs, candidates, options, progress);
  EXPECT_EQ(max_inside, 1);
  EXPECT_TRUE(monotonic);
  EXPECT_DOUBLE_EQ(last_fraction, 1.0);
  EXPECT_EQ(parallel.chosen, serial.chosen);
  EXPECT_EQ(parallel.rule, serial.rule);
  ASSERT_EQ(parallel.candidates.size(), serial.candidates.size());
  for (size_t k = 0; k < serial.candidates.size(); ++k) {
    const RigModelScore& a = parallel.candidates[k];
    const RigModelScore& b = serial.candidates[k];
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.fit.baseline_m, b.fit.baseline_m) << b.name;
    EXPECT_EQ(a.fit.rms_px, b.fit.rms_px) << b.name;
    EXPECT_EQ(a.fold_rms_px, b.fold_rms_px) << b.name;
    EXPECT_EQ(a.cv_excess_mse_px2, b.cv_excess_mse_px2) << b.name;
  }
}

// Cancelled while candidates run on several threads: the call throws, it does not hang.
TEST(RigModelSelection, CancellationStopsEveryThread) {
  const Scene scene = MakeScene(0.0, 6, 31);
  RelativePoseOptions options;
  options.num_threads = 4;
  int num_reports = 0;
  ProgressSink progress;
  progress.report = [&num_reports](double, const std::string&, const std::string&) {
    ++num_reports;
  };
  progress.is_cancelled = [&num_reports] { return num_reports >= 2; };
  EXPECT_THROW(SelectRigIntrinsicsModel(scene.board, scene.pairs,
                                        Candidates(scene.rig.cam0, scene.rig.cam1), options,
                                        progress),
               Cancelled);
  EXPECT_GE(num_reports, 2);
}

TEST(RigModelSelection, CancellationThrows) {
  const Scene scene = MakeScene(0.0, 4, 29);
  ProgressSink cancelled;
  cancelled.is_cancelled = [] { return true; };
  EXPECT_THROW(SelectRigIntrinsicsModel(scene.board, scene.pairs,
                                        Candidates(scene.rig.cam0, scene.rig.cam1), {}, cancelled),
               Cancelled);
}

}  // namespace
}  // namespace omnirig
