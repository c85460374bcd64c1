#include "engine/calib/calibrate.h"

#include <memory>
#include <random>

#include <gtest/gtest.h>

#include "engine/calib/initialize.h"
#include "engine/estimators/board_pose.h"
#include "testing/calib/synthetic_corners.h"

namespace omnirig {
namespace {

CameraModel TrueCamera() {
  CameraModel camera;
  camera.width = 1024;
  camera.height = 768;
  camera.intrinsics.params = {0.9,   310.0, 305.0, 515.0,   380.0, 0.0,
                              -0.12, 0.03,  0.001, -0.0015, 0.0};
  return camera;
}

// Mean angle between true and calibrated rays over a pixel grid on the annulus around the
// principal point that the boards cover (the calibrated part of the mirror disk).
double MeanRayErrorDeg(const CameraModel& truth, const CameraModel& estimate,
                       const SyntheticCornerSet& set) {
  const Eigen::Vector2d centre(truth.intrinsics.u0(), truth.intrinsics.v0());
  double r_min = 1e9, r_max = 0.0;
  for (const auto& view : set.views) {
    for (const auto& corner : view.detection.corners_px) {
      r_min = std::min(r_min, (corner - centre).norm());
      r_max = std::max(r_max, (corner - centre).norm());
    }
  }
  double sum = 0.0;
  int n = 0;
  for (int v = 0; v < truth.height; v += 10) {
    for (int u = 0; u < truth.width; u += 10) {
      const Eigen::Vector2d pixel(u, v);
      const double r = (pixel - centre).norm();
      if (r < r_min || r > r_max) continue;
      const auto a = Lift(truth.intrinsics, pixel);
      const auto b = Lift(estimate.intrinsics, pixel);
      if (!a || !b) return 1e9;
      sum += std::acos(std::clamp(a->dot(*b), -1.0, 1.0));
      ++n;
    }
  }
  return n > 0 ? sum / n * 180.0 / M_PI : 1e9;
}

TEST(Calibrate, RecoversExactSyntheticCorners) {
  const CameraModel truth = TrueCamera();
  SyntheticCornerOptions synth;
  synth.num_views = 12;
  const SyntheticCornerSet set = MakeSyntheticCornerSet(truth, SyntheticBoard(), synth);
  const CalibrationReport report =
      Calibrate(set.views, truth.width, truth.height, SyntheticBoard(), CalibrationOptions(), {});
  EXPECT_EQ(report.num_views_used, 12);
  EXPECT_LT(report.rms_px, 1e-6);
  EXPECT_LT(MeanRayErrorDeg(truth, report.camera, set), 1e-5);
  for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
    EXPECT_NEAR(report.camera.intrinsics.params[i], truth.intrinsics.params[i],
                1e-5 * std::max(1.0, std::abs(truth.intrinsics.params[i])))
        << UnifiedIntrinsics::kNames[i];
  }
  for (size_t v = 0; v < set.views.size(); ++v) {
    EXPECT_LT(
        (report.images[v].cam_from_board.translation - set.cam_from_board[v].translation).norm(),
        1e-6);
  }
}

TEST(Calibrate, NoisyCornersGiveSmallStdAndRayError) {
  const CameraModel truth = TrueCamera();
  SyntheticCornerOptions synth;
  synth.noise_px = 0.2;
  synth.seed = 7;
  const SyntheticCornerSet set = MakeSyntheticCornerSet(truth, SyntheticBoard(), synth);
  const CalibrationReport report =
      Calibrate(set.views, truth.width, truth.height, SyntheticBoard(), CalibrationOptions(), {});
  // sqrt(2) * 0.2 px per corner, less the fitted parameters.
  EXPECT_NEAR(report.rms_px, 0.2 * std::sqrt(2.0), 0.03);
  EXPECT_LT(MeanRayErrorDeg(truth, report.camera, set), 0.1);
  EXPECT_GT(report.intrinsics_std[UnifiedIntrinsics::kU0], 0.0);
  EXPECT_LT(report.intrinsics_std[UnifiedIntrinsics::kU0], 1.0);
  EXPECT_EQ(report.intrinsics_std[UnifiedIntrinsics::kAlpha], 0.0);  // fixed
  EXPECT_EQ(report.intrinsics_std[UnifiedIntrinsics::kK5], 0.0);
  EXPECT_NEAR(report.mean_px * report.mean_px + report.std_px * report.std_px,
              report.rms_px * report.rms_px, 1e-9);
}

TEST(Calibrate, RejectsOutlierCorners) {
  const CameraModel truth = TrueCamera();
  SyntheticCornerOptions synth;
  synth.noise_px = 0.1;
  synth.outlier_fraction = 0.03;
  synth.seed = 11;
  const SyntheticCornerSet set = MakeSyntheticCornerSet(truth, SyntheticBoard(), synth);
  const CalibrationReport report =
      Calibrate(set.views, truth.width, truth.height, SyntheticBoard(), CalibrationOptions(), {});
  int planted = 0, caught = 0, wrongly = 0;
  for (size_t v = 0; v < set.views.size(); ++v) {
    ASSERT_TRUE(report.images[v].used) << report.images[v].reason;
    for (size_t i = 0; i < set.is_outlier[v].size(); ++i) {
      planted += set.is_outlier[v][i];
      caught += set.is_outlier[v][i] && !report.images[v].inlier[i];
      wrongly += !set.is_outlier[v][i] && !report.images[v].inlier[i];
    }
  }
  ASSERT_GT(planted, 10);
  EXPECT_EQ(caught, planted);
  EXPECT_LE(wrongly, 2);
  EXPECT_LT(report.rms_px, 0.2);
  EXPECT_GT(report.rms_all_px, 1.0);
  // Statistical: about 2 sigma of the principal point (std ~0.3 px) on this weak geometry.
  EXPECT_LT(MeanRayErrorDeg(truth, report.camera, set), 0.2);
  // Several solves (robust rounds, then a plain one): the brief counts them all, as the
  // report's iterations do.
  ASSERT_GT(report.solver.num_rounds, 1);
  EXPECT_NE(report.solver.brief.find("Iterations: " + std::to_string(report.solver.num_iterations) +
                                     " over " + std::to_string(report.solver.num_rounds)),
            std::string::npos)
      << report.solver.brief;
}

TEST(Calibrate, FixedParametersStayPut) {
  const CameraModel truth = TrueCamera();
  SyntheticCornerOptions synth;
  synth.noise_px = 0.1;
  const SyntheticCornerSet set = MakeSyntheticCornerSet(truth, SyntheticBoard(), synth);
  CalibrationOptions options;
  options.SetFixed("xi", true);
  options.SetFixed("tangential", true);
  const CalibrationReport report =
      Calibrate(set.views, truth.width, truth.height, SyntheticBoard(), options, {});
  EXPECT_EQ(report.camera.intrinsics.xi(), 1.0);  // the initial value
  EXPECT_EQ(report.camera.intrinsics.k(3), 0.0);
  EXPECT_EQ(report.camera.intrinsics.k(4), 0.0);
  EXPECT_EQ(report.intrinsics_std[UnifiedIntrinsics::kXi], 0.0);
}

TEST(Calibrate, TooFewViewsListsEveryReason) {
  const CameraModel truth = TrueCamera();
  SyntheticCornerOptions synth;
  synth.num_views = 2;
  SyntheticCornerSet set = MakeSyntheticCornerSet(truth, SyntheticBoard(), synth);
  CalibrationView missing;
  missing.name = "empty.png";
  missing.detection.reason = "no checkerboard 8x6 found";
  set.views.push_back(missing);
  try {
    Calibrate(set.views, truth.width, truth.height, SyntheticBoard(), CalibrationOptions(), {});
    FAIL() << "expected InvalidArgument";
  } catch (const InvalidArgument& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("at least 3 usable views, got 2"), std::string::npos) << message;
    EXPECT_NE(message.find("empty.png: no checkerboard 8x6 found"), std::string::npos) << message;
    EXPECT_NE(message.find("view0: usable"), std::string::npos) << message;
  }
}

TEST(Calibrate, BadInputsThrow) {
  CalibrationOptions options;
  EXPECT_THROW(options.SetFixed("k9", true), InvalidArgument);
  options.num_threads = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  BoardSpec board = SyntheticBoard();
  board.square_size_m = 40.0;  // metres: absurd
  EXPECT_THROW(board.Check(), InvalidArgument);
  board = SyntheticBoard();
  board.cols = 1;
  EXPECT_THROW(board.Check(), InvalidArgument);
  EXPECT_THROW(Calibrate({}, 0, 768, SyntheticBoard(), CalibrationOptions(), {}), InvalidArgument);
  CalibrationView bad;
  bad.detection.found = true;
  bad.detection.corners_px.resize(10);
  bad.detection.corner_ids.assign(10, 99);
  EXPECT_THROW(Calibrate({bad, bad, bad}, 640, 480, SyntheticBoard(), CalibrationOptions(), {}),
               InvalidArgument);
}

TEST(Calibrate, CancelsThroughTheSink) {
  const CameraModel truth = TrueCamera();
  const SyntheticCornerSet set = MakeSyntheticCornerSet(truth, SyntheticBoard(), {});
  ProgressSink sink;
  int reports = 0;
  sink.report = [&](double, const std::string& stage, const std::string&) {
    reports += stage == "solve";
  };
  sink.is_cancelled = [&] { return reports >= 2; };
  EXPECT_THROW(
      Calibrate(set.views, truth.width, truth.height, SyntheticBoard(), CalibrationOptions(), sink),
      Cancelled);
}

TEST(Initialize, GammaFromLineIsExactForXiOne) {
  CameraModel camera = TrueCamera();
  camera.intrinsics.params = {1.0, 300.0, 300.0, 500.0, 400.0, 0, 0, 0, 0, 0, 0};
  std::vector<Eigen::Vector2d> pixels;
  for (int i = 0; i < 8; ++i) {
    pixels.push_back(*Project(camera.intrinsics, Eigen::Vector3d(0.5, -0.3 + 0.1 * i, 0.2)));
  }
  const auto gamma = GammaFromLine(pixels, Eigen::Vector2d(500.0, 400.0));
  ASSERT_TRUE(gamma);
  EXPECT_NEAR(*gamma, 300.0, 1e-6);
}

TEST(BoardPose, RecoversThePoseWithTheModelFixed) {
  const CameraModel truth = TrueCamera();
  SyntheticCornerOptions synth;
  synth.num_views = 5;
  const SyntheticCornerSet set = MakeSyntheticCornerSet(truth, SyntheticBoard(), synth);
  for (size_t v = 0; v < set.views.size(); ++v) {
    double rms = -1.0;
    const auto pose = EstimateBoardPose(truth, SyntheticBoard().ObjectPoints(),
                                        set.views[v].detection.corners_px, &rms);
    ASSERT_TRUE(pose);
    EXPECT_LT(rms, 1e-8);
    EXPECT_LT((pose->translation - set.cam_from_board[v].translation).norm(), 1e-8);
    EXPECT_LT(RotationDistanceRad(pose->rotation, set.cam_from_board[v].rotation), 1e-8);
  }
  EXPECT_FALSE(EstimateBoardPose(truth, {}, {}));
}

}  // namespace
}  // namespace omnirig
