// The relative pose on real fisheye stereo pairs (label integration): detection, per-camera
// calibration and the rig, against the reference baseline of the data's own repository
// (cv::fisheye::stereoCalibrate, Kannala-Brandt model: 109.96 mm). The same pairs' own
// uncertainty is large: leaving one pair out moves our baseline by up to 0.6 mm (bench_relpose).

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <optional>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "engine/calib/calibrate.h"
#include "engine/calib/detect.h"
#include "engine/rig/relative_pose.h"
#include "engine/rig/relpose_model_select.h"

namespace omnirig {
namespace {

std::filesystem::path DataDir() {
  const char* source = std::getenv("OMNIRIG_SOURCE_DIR");
  return std::filesystem::path(source != nullptr ? source : ".") / ".." / "shared" / "data" /
         "real" / "fisheye-stereo-pairs";
}

CameraModel CalibrateCamera(const std::vector<StereoBoardPair>& pairs, int camera,
                            const BoardSpec& board,
                            const CalibrationOptions& options = CalibrationOptions()) {
  std::vector<CalibrationView> views;
  for (const StereoBoardPair& pair : pairs) {
    views.push_back({pair.name, camera == 0 ? pair.cam0 : pair.cam1});
  }
  return Calibrate(views, 960, 600, board, options, ProgressSink()).camera;
}

class RelativePoseReal : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const std::filesystem::path dir = DataDir();
    if (!std::filesystem::is_directory(dir)) return;
    board_.cols = 9;
    board_.rows = 6;
    board_.square_size_m = 0.02423;
    pairs_ = new std::vector<StereoBoardPair>();
    for (int i = 1; i <= 29; ++i) {
      const cv::Mat left =
          cv::imread((dir / ("left" + std::to_string(i) + ".jpg")).string(), cv::IMREAD_GRAYSCALE);
      const cv::Mat right =
          cv::imread((dir / ("right" + std::to_string(i) + ".jpg")).string(), cv::IMREAD_GRAYSCALE);
      if (left.empty() || right.empty()) continue;
      pairs_->push_back({"pair" + std::to_string(i), DetectBoard(left, board_, DetectOptions()),
                         DetectBoard(right, board_, DetectOptions())});
    }
  }
  static void TearDownTestSuite() {
    delete pairs_;
    pairs_ = nullptr;
  }
  void SetUp() override {
    if (pairs_ == nullptr) {
      GTEST_SKIP() << "real data not found at " << DataDir() << " (../shared/data/real)";
    }
    ASSERT_EQ(pairs_->size(), 29u) << "an image of the 29 pairs did not load";
  }

  // Each camera calibrated from its own 29 images, default fixed set (tangential = false) or
  // with k3 = k4 = 0 too; computed once for the whole suite.
  static const CameraModel& Camera(int camera, bool no_tangential) {
    static std::optional<CameraModel> cache[2][2];
    std::optional<CameraModel>& cached = cache[camera][no_tangential ? 1 : 0];
    if (!cached) {
      CalibrationOptions options;
      options.SetFixed("tangential", no_tangential);
      cached = CalibrateCamera(*pairs_, camera, board_, options);
    }
    return *cached;
  }

  // The rig with the intrinsics refined, default fixed set and synchronisation test (the
  // "free" model): several tests check different properties of this estimate, computed once.
  static const RelativePoseReport& JointEstimate() {
    static std::optional<RelativePoseReport> estimate;
    if (!estimate) {
      RelativePoseOptions options;
      options.refine_intrinsics = true;
      estimate = EstimateRelativePose(Camera(0, false), Camera(1, false), board_, *pairs_, options);
    }
    return *estimate;
  }

  static BoardSpec board_;
  static std::vector<StereoBoardPair>* pairs_;
};

BoardSpec RelativePoseReal::board_;
std::vector<StereoBoardPair>* RelativePoseReal::pairs_ = nullptr;

TEST_F(RelativePoseReal, FisheyePairsGiveTheReferenceBaseline) {
  const RelativePoseReport& report = JointEstimate();
  ASSERT_TRUE(report.success) << report.message;
  // The synchronisation test may leave out up to half the pairs, each with its reason.
  EXPECT_GE(report.num_pairs_used, 15);
  for (const RelativePosePairReport& pair : report.pairs) {
    EXPECT_TRUE(pair.used || !pair.reason.empty()) << pair.name;
  }
  EXPECT_LT(report.rms_px, 0.5);
  // Left camera = cam0: the right camera sits ~110 mm along cam0's +x.
  EXPECT_GT(report.rig.cam0_from_cam1.translation.x(), 0.1);
  // The README's figure for this configuration ("free"): 109.74 mm (-0.20 % of the
  // reference), to the stated precision. The figures are stated to 0.01 mm, not 0.001: the
  // solver's stopping rule and another CPU's rounding move them by about 0.5 micrometre (a run on
  // 2026-11-25 measured 109.7400, the next CI run 109.7395), still 100 times below the covariance's
  // std (0.059 mm).
  EXPECT_NEAR(report.baseline_m, 0.10974, 0.005e-3);
  EXPECT_LT(RotationDistanceRad(report.rig.cam0_from_cam1.rotation, Eigen::Quaterniond::Identity()),
            3.0 * M_PI / 180.0);
}

// The model, not the method, sets where the baseline lands on these pairs: under eq. 20 alone
// (the default), without the tangential terms (k3, k4) the unified model has the
// Kannala-Brandt reference's degrees of freedom and lands on its baseline, at almost the same
// RMS; with them it lands 0.4 % shorter, many times eq. 20's covariance standard deviation
// away (bench_relpose prints both next to cv::fisheye and cv::omnidir on the same corners).
TEST_F(RelativePoseReal, TangentialTermsMoveTheBaselineByMoreThanItsStd) {
  const RelativePoseReport& with_tangential = JointEstimate();
  RelativePoseOptions options;
  options.refine_intrinsics = true;
  options.fixed_intrinsics[UnifiedIntrinsics::kK3] = true;
  options.fixed_intrinsics[UnifiedIntrinsics::kK4] = true;
  const RelativePoseReport without =
      EstimateRelativePose(Camera(0, true), Camera(1, true), board_, *pairs_, options);
  ASSERT_TRUE(with_tangential.success) << with_tangential.message;
  ASSERT_TRUE(without.success) << without.message;
  EXPECT_EQ(without.rig.cam0.intrinsics.params[UnifiedIntrinsics::kK3], 0.0);
  EXPECT_LT(without.rms_px, with_tangential.rms_px + 0.02);
  EXPECT_GT(without.baseline_m - with_tangential.baseline_m, 3.0 * with_tangential.baseline_std_m);
  // The README's figure for "tangential_fixed": 110.00 mm (+0.04 %), 0.232 px.
  EXPECT_NEAR(without.baseline_m, 0.11000, 0.005e-3);
  EXPECT_NEAR(without.rms_px, 0.232, 0.0005);
}

// Some pairs' two images do not show one board pose: before the synchronisation test existed,
// the pairs whose joint residual was well above the mono calibrations' were traced to pairs 11,
// 15 and 22, whose two cameras' own board poses disagree by 2 to 3 mm at the board's centre.
// The test (relpose_sync.h, its rule fixed on synthetic rigs) must leave those out, keep most
// pairs, and the rig without them must fit the rest at close to the mono calibrations' level.
TEST_F(RelativePoseReal, UnsynchronisedPairsAreLeftOut) {
  const RelativePoseReport& report = JointEstimate();
  RelativePoseOptions options;
  options.refine_intrinsics = true;
  options.sync_test.false_alarm_rate = 0.0;
  const RelativePoseReport kept =
      EstimateRelativePose(Camera(0, false), Camera(1, false), board_, *pairs_, options);
  ASSERT_TRUE(report.success) << report.message;
  ASSERT_TRUE(kept.success) << kept.message;
  EXPECT_EQ(report.num_pairs_used, 29 - report.sync_rounds);
  for (const char* name : {"pair11", "pair15", "pair22"}) {
    const auto pair = std::find_if(report.pairs.begin(), report.pairs.end(),
                                   [name](const RelativePosePairReport& p) { return p.name == name; });
    ASSERT_NE(pair, report.pairs.end());
    EXPECT_FALSE(pair->used) << name;
    EXPECT_NE(pair->reason.find("exposures not simultaneous?"), std::string::npos) << pair->reason;
    EXPECT_GT(pair->board_offset_m, 1e-3) << name;
  }
  // Each camera's corner noise as its own calibration sees it (0.16-0.18 px RMS of the
  // Euclidean error: 0.11-0.13 px per coordinate).
  for (double noise : report.sync_test.corner_noise_px) {
    EXPECT_GT(noise, 0.10);
    EXPECT_LT(noise, 0.14);
  }
  EXPECT_LT(report.rms_px, kept.rms_px);
  EXPECT_LT(report.rms_px, 2.0 * std::sqrt(2.0) * report.sync_test.corner_noise_px[1]);
}

// The kept pairs disagree far beyond their corner noise, so eq. 20's covariance understates the
// baseline's uncertainty (0.06 mm against a leave-one-pair-out jackknife of about 0.5 mm in
// bench_relpose); the cluster-robust std over pairs (relpose_refine.h) must see that spread
// (bench_relpose: 0.27 mm), and stay within the jackknife's order.
TEST_F(RelativePoseReal, ClusterRobustStdSeesThePairsDisagreement) {
  const RelativePoseReport& report = JointEstimate();
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_GT(report.baseline_std_robust_m, 3.0 * report.baseline_std_m);
  EXPECT_LT(report.baseline_std_robust_m, 1e-3);
  EXPECT_GT(report.rotation_std_robust_deg, report.rotation_std_deg);
}

// The job's default on these pairs: the five candidate models (AutoRigIntrinsicsModels) scored
// by leave-one-pair-out prediction of one camera's corners from the other's (bench_relpose
// prints the table).
TEST_F(RelativePoseReal, CrossValidationScoresEveryModelAndFollowsItsRule) {
  std::vector<RigModelCandidate> candidates;
  for (const RigIntrinsicsModel& model : AutoRigIntrinsicsModels(DefaultFixedIntrinsics())) {
    candidates.push_back({model, Camera(0, model.CalibrationFixed(0)[UnifiedIntrinsics::kK3]),
                          Camera(1, model.CalibrationFixed(1)[UnifiedIntrinsics::kK3])});
  }
  // Two threads, as a job with two: the same result as one (relpose_model_select_test.cc),
  // half the wall time on a quiet machine.
  RelativePoseOptions options;
  options.num_threads = 2;
  const RigModelSelection selection =
      SelectRigIntrinsicsModel(board_, *pairs_, candidates, options);
  EXPECT_GE(selection.held_out.size(), 15u);
  ASSERT_GE(selection.chosen, 0) << selection.rule;
  for (const RigModelScore& score : selection.candidates) {
    ASSERT_TRUE(score.fit.success) << score.name << ": " << score.fit.message;
    EXPECT_GT(score.cv_rms_px, score.fit.rms_px) << score.name;
  }
  // Each camera's own calibration, kept, predicts the other camera worst of the three.
  const RigModelScore& fixed = selection.candidates[0];
  for (size_t k = 1; k < selection.candidates.size(); ++k) {
    EXPECT_GT(fixed.cv_rms_px, selection.candidates[k].cv_rms_px) << selection.candidates[k].name;
  }
  const RigModelScore& chosen = selection.candidates[selection.chosen];
  EXPECT_LE(chosen.cv_excess_mse_px2, chosen.cv_excess_se_px2);
  for (int k = 0; k < selection.chosen; ++k) {  // every simpler model is more than 1 SE worse
    EXPECT_GT(selection.candidates[k].cv_excess_mse_px2, selection.candidates[k].cv_excess_se_px2);
  }
  // The job's default: "tangential_free_cam0", 109.74 mm (-0.21 %), 0.225 px, 21 of 29 pairs
  // (docs/relpose.md). The folds are the pairs every candidate kept: since the synchronisation
  // test expects the held-out rig's own error at a pair (a144b07), the "fixed" candidate keeps
  // pair 12 too (statistic 24.2 against 24.22), "tangential_fixed" (110.00 mm) is 1.4 standard
  // errors worse than "free" and the rule chooses "tangential_free_cam0".
  EXPECT_EQ(chosen.name, "tangential_free_cam0");
  EXPECT_NEAR(chosen.fit.baseline_m, 0.109736, 0.005e-3);  // 109.736 mm, stated as 109.74
  EXPECT_NEAR(chosen.fit.rms_px, 0.225, 0.0005);
  EXPECT_EQ(chosen.fit.num_pairs_used, 21);
}

}  // namespace
}  // namespace omnirig
