// The `relative_pose` job end to end on synthetic renders (label integration): images written
// to a dataset folder as cam0/NAME and cam1/NAME, corners from omnirig's own detector.

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <random>
#include <sstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "api/calibration_job.h"
#include "api/camera_json.h"
#include "api/relpose_job.h"
#include "engine/calib/calibrate.h"
#include "engine/calib/model_io.h"
#include "engine/calib/detect.h"
#include "engine/synth/presets.h"
#include "testing/synth/calib_board.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

class RelposeJob : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    synth::StereoBoardOptions options = synth::QuickStereoBoardOptions(8, 5);
    set_ = new synth::StereoBoardSet(synth::MakeStereoBoardSet(options));
    dir_ = new std::filesystem::path(std::filesystem::temp_directory_path() /
                                     ("omnirig_relpose_job_" +
                                      std::to_string(std::random_device()())));
    for (int c = 0; c < 2; ++c) {
      std::filesystem::create_directories(*dir_ / ("cam" + std::to_string(c)));
      for (size_t i = 0; i < set_->names.size(); ++i) {
        cv::imwrite((*dir_ / ("cam" + std::to_string(c)) / (set_->names[i] + ".png")).string(),
                    set_->images[c][i]);
      }
    }
  }
  static void TearDownTestSuite() {
    std::filesystem::remove_all(*dir_);
    delete dir_;
    delete set_;
  }

  JobContext Context() const {
    JobContext context;
    context.dataset_dir = *dir_;
    for (const char* camera : {"cam0", "cam1"}) {
      for (const std::string& name : set_->names) {
        context.image_names.push_back(std::string(camera) + "/" + name + ".png");
      }
    }
    std::sort(context.image_names.begin(), context.image_names.end());
    context.load_result = [](const std::string& id) -> json {
      return {{"camera", CameraToJson(id == "truth0" ? set_->rig.cam0 : set_->rig.cam1)}};
    };
    return context;
  }
  static json Board() {
    return {{"cols", set_->board.cols},
            {"rows", set_->board.rows},
            {"square_size_mm", set_->board.square_size_m * 1e3}};
  }

  static synth::StereoBoardSet* set_;
  static std::filesystem::path* dir_;
};

synth::StereoBoardSet* RelposeJob::set_ = nullptr;
std::filesystem::path* RelposeJob::dir_ = nullptr;

TEST_F(RelposeJob, WithCalibrationsRecoversTheRenderedRig) {
  JobContext context = Context();
  double last_fraction = -1.0;
  bool monotone = true;
  std::string last_stage, last_message;
  context.progress.report = [&](double fraction, const std::string& stage,
                                const std::string& message) {
    monotone = monotone && fraction >= last_fraction - 1e-12;
    last_fraction = fraction;
    last_stage = stage;
    last_message = message;
  };
  // "fixed": the given cameras kept (without it the job may refine them, the test below).
  const json params = {{"board", Board()},
                       {"calibrations", {{"cam0", "truth0"}, {"cam1", "truth1"}}},
                       {"intrinsics_model", "fixed"}};
  const json result = RunRelativePoseJob(params, context);
  const StereoRig rig = RigFromJson(result);
  const Rigid3d& truth = set_->rig.cam0_from_cam1;
  const double baseline_error_m = rig.cam0_from_cam1.translation.norm() - truth.translation.norm();
  EXPECT_LT(std::abs(baseline_error_m), 1e-4);  // 0.1% of the 100 mm baseline
  EXPECT_LT(std::abs(baseline_error_m), 5.0 * result["baseline_std_m"].get<double>() + 1e-5);
  EXPECT_LT(std::abs(baseline_error_m), 5.0 * result["baseline_std_robust_m"].get<double>() + 1e-5);
  EXPECT_LT((rig.cam0_from_cam1.translation - truth.translation).norm(), 5e-4);
  EXPECT_LT(RotationDistanceRad(rig.cam0_from_cam1.rotation, truth.rotation) * 180.0 / M_PI,
            0.05);
  EXPECT_LT(result["rms_px"].get<double>(), 0.3);
  // Every pair is used: the exposures are simultaneous by construction. (Before the detector's
  // grid check, corner 47 of cam1/pair_007 was 3.9 px off, that pair's joint RMS 0.40 px against
  // 0.02 px, and the synchronisation test rightly left it out; engine/calib/grid_check.h.)
  EXPECT_EQ(result["num_pairs_used"].get<int>(), 8);
  for (const json& pair : result["pairs"]) {
    if (pair["used"].get<bool>()) continue;
    EXPECT_NE(pair["reason"].get<std::string>().find("not simultaneous"), std::string::npos)
        << pair.dump();
    EXPECT_GT(pair["sync_statistic"].get<double>(), result["sync_test"]["limit"].get<double>());
  }
  EXPECT_TRUE(result["sync_test"]["run"].get<bool>());
  EXPECT_EQ(result["calibrations"]["cam0"]["job_id"], "truth0");
  EXPECT_EQ(result["cameras"]["cam1"], CameraToJson(set_->rig.cam1));
  EXPECT_EQ(result["intrinsics_model"]["selection"], "given");
  EXPECT_FALSE(result["intrinsics_model"].contains("candidates"));
  EXPECT_TRUE(monotone);
  EXPECT_NEAR(last_fraction, 1.0, 1e-9);
  // The job ends on its summary, not a bare "done".
  EXPECT_EQ(last_stage, "done");
  std::ostringstream baseline;
  baseline << std::fixed << std::setprecision(2) << "baseline "
           << result["baseline_m"].get<double>() * 1e3 << " +- ";
  EXPECT_EQ(last_message.rfind(baseline.str(), 0), 0u) << last_message;
  EXPECT_NE(last_message.find(" mm, rotation "), std::string::npos) << last_message;
  EXPECT_NE(last_message.find("8 of 8 pairs used"), std::string::npos) << last_message;
}

// The cameras given as a Kalibr camchain of the dataset (as a user who calibrated with Kalibr
// has them): taken as given calibrations, the camchain's own extrinsic reported beside.
TEST_F(RelposeJob, WithAKalibrCamchainOfTheDataset) {
  StereoRig chain = set_->rig;
  chain.cam0_from_cam1.translation *= 1.02;  // Kalibr's extrinsic, not this job's estimate
  {
    std::ofstream file(*dir_ / "camchain.yaml");
    file << ToKalibrCamchain(chain, nullptr);
  }
  const json result = RunRelativePoseJob(
      {{"board", Board()}, {"calibrations", "camchain.yaml"}, {"intrinsics_model", "fixed"}},
      Context());
  std::filesystem::remove(*dir_ / "camchain.yaml");
  const StereoRig rig = RigFromJson(result);
  const double truth_m = set_->rig.cam0_from_cam1.translation.norm();
  EXPECT_LT(std::abs(rig.cam0_from_cam1.translation.norm() - truth_m), 1e-4);
  EXPECT_EQ(result["calibrations"]["cam0"]["source"], "kalibr_camchain");
  EXPECT_EQ(result["calibrations"]["cam1"]["file"], "camchain.yaml");
  EXPECT_EQ(result["cameras"]["cam1"], CameraToJson(set_->rig.cam1));
  EXPECT_NEAR(result["kalibr_camchain"]["baseline_m"].get<double>(), 1.02 * truth_m, 1e-9);
}

// Given calibrations made from each camera's 8 pair images and 8 views of its own (another
// render set's): the default ("auto") chooses between keeping them and refining them with the
// rig, using their 8 own views (the pair images among their views are recognised and not
// counted twice), and the result says which observations it used.
TEST_F(RelposeJob, WithCalibrationsUsesTheirViewsToo) {
  const synth::StereoBoardSet mono = synth::MakeStereoBoardSet(synth::QuickStereoBoardOptions(8, 6));
  const BoardSpec board = ToBoardSpec(set_->board);
  std::array<json, 2> calibrations;
  for (int c = 0; c < 2; ++c) {
    std::vector<CalibrationView> views;
    for (size_t i = 0; i < set_->names.size(); ++i) {
      views.push_back({"pair_" + set_->names[i], DetectBoard(set_->images[c][i], board, DetectOptions())});
      views.push_back({"mono_" + mono.names[i], DetectBoard(mono.images[c][i], board, DetectOptions())});
    }
    const CameraModel& size_of = c == 0 ? set_->rig.cam0 : set_->rig.cam1;
    calibrations[c] = CalibrationReportToJson(
        Calibrate(views, size_of.width, size_of.height, board, CalibrationOptions(), ProgressSink()));
  }
  JobContext context = Context();
  context.load_result = [&calibrations](const std::string& id) -> json {
    return calibrations[id == "cal0" ? 0 : 1];
  };
  std::string last_message;
  context.progress.report = [&](double, const std::string&, const std::string& message) {
    last_message = message;
  };
  const json result = RunRelativePoseJob(
      {{"board", Board()}, {"calibrations", {{"cam0", "cal0"}, {"cam1", "cal1"}}}}, context);
  const json& model = result["intrinsics_model"];
  EXPECT_EQ(model["selection"], "cross_validation");
  ASSERT_EQ(model["candidates"].size(), 2u);  // fixed, free: given calibrations are not redone
  EXPECT_EQ(model["candidates"][0]["name"], "fixed");
  EXPECT_EQ(model["candidates"][1]["name"], "free");
  const json& observations = result["observations"];
  EXPECT_EQ(observations["pairs_given"].get<int>(), 8);
  EXPECT_EQ(observations["pairs_used"].get<int>(), 8);
  int mono_found = 0;
  for (int c = 0; c < 2; ++c) {
    for (const cv::Mat& image : mono.images[c]) {
      mono_found += DetectBoard(image, board, DetectOptions()).found ? 1 : 0;
    }
  }
  EXPECT_EQ(observations["single_camera_views_given"].get<int>(), mono_found);
  EXPECT_GE(mono_found, 12);
  const bool refined = result["intrinsics_refined"].get<bool>();
  EXPECT_EQ(observations["single_camera_views_used"].get<int>(), refined ? mono_found : 0);
  ASSERT_EQ(result["single_camera_views"].size(), static_cast<size_t>(mono_found));
  for (const json& view : result["single_camera_views"]) {
    EXPECT_EQ(view["used"].get<bool>(), refined) << view.dump();
    EXPECT_NE(view["name"].get<std::string>().find("calibration view mono_"), std::string::npos);
  }
  EXPECT_EQ(result["pairs"].size(), 8u);
  EXPECT_NEAR(result["baseline_m"].get<double>(), set_->rig.cam0_from_cam1.translation.norm(),
              5e-4);
  // The chosen candidate's summary, not the last candidate's.
  std::ostringstream chosen_baseline;
  chosen_baseline << std::fixed << std::setprecision(2) << "baseline "
                  << result["baseline_m"].get<double>() * 1e3 << " +- ";
  EXPECT_EQ(last_message.rfind(chosen_baseline.str(), 0), 0u) << last_message;
}

TEST_F(RelposeJob, WithoutCalibrationsCalibratesEachCameraFirst) {
  const json result = RunRelativePoseJob({{"board", Board()}}, Context());
  EXPECT_EQ(result["calibrations"]["cam0"]["source"], "calibrated");
  EXPECT_LT(result["calibrations"]["cam0"]["rms_px"].get<double>(), 0.5);
  EXPECT_EQ(result["cameras"]["cam0"]["image_size"][0], 800);
  // Eight views calibrate each camera loosely; refined with the rig (the default here), the
  // cameras give the baseline to a fraction of a millimetre.
  EXPECT_TRUE(result["intrinsics_refined"].get<bool>());
  const double baseline_m = result["baseline_m"].get<double>();
  EXPECT_NEAR(baseline_m, set_->rig.cam0_from_cam1.translation.norm(), 5e-4);
  EXPECT_LT(result["rms_px"].get<double>(), 0.5);
  // The default chooses the intrinsics model by cross-validation and reports the evidence;
  // the result is the chosen candidate's fit.
  const json& model = result["intrinsics_model"];
  EXPECT_EQ(model["selection"], "cross_validation");
  EXPECT_EQ(model["held_out_pairs"].get<int>(), 8);  // every pair, as in the test above
  // fixed, tangential_fixed, tangential_free_cam0, tangential_free_cam1, free.
  ASSERT_EQ(model["candidates"].size(), 5u);
  EXPECT_EQ(model["candidates"][2]["name"], "tangential_free_cam0");
  int num_chosen = 0;
  for (const json& candidate : model["candidates"]) {
    EXPECT_TRUE(candidate["success"].get<bool>()) << candidate.dump();
    EXPECT_GT(candidate["cv_rms_px"].get<double>(), candidate["rms_px"].get<double>());
    EXPECT_GE(candidate["cv_excess_mse_px2"].get<double>(), 0.0);
    if (candidate["name"] != model["chosen"]) continue;
    ++num_chosen;
    EXPECT_EQ(candidate["baseline_m"].get<double>(), baseline_m);
    EXPECT_LE(candidate["cv_excess_mse_px2"].get<double>(),
              candidate["cv_excess_se_px2"].get<double>());
  }
  EXPECT_EQ(num_chosen, 1);
  EXPECT_NE(model["rule"].get<std::string>().find("one standard error"), std::string::npos);
}

// A per-camera model named by the user: the other camera is calibrated with k3 = k4 = 0 and
// keeps them at 0 in the joint fit, the named camera's tangential terms are refined.
TEST_F(RelposeJob, NamedPerCameraModelFreesOneCameraOnly) {
  const json result =
      RunRelativePoseJob({{"board", Board()}, {"intrinsics_model", "tangential_free_cam1"}},
                         Context());
  EXPECT_EQ(result["intrinsics_model"]["chosen"], "tangential_free_cam1");
  EXPECT_EQ(result["intrinsics_model"]["selection"], "given");
  EXPECT_TRUE(result["intrinsics_refined"].get<bool>());
  const json& cam0 = result["cameras"]["cam0"]["intrinsics"];
  const json& cam1 = result["cameras"]["cam1"]["intrinsics"];
  EXPECT_EQ(cam0["k3"].get<double>(), 0.0);
  EXPECT_EQ(cam0["k4"].get<double>(), 0.0);
  EXPECT_NE(cam1["k3"].get<double>(), 0.0);
  EXPECT_NE(cam1["k4"].get<double>(), 0.0);
  EXPECT_NEAR(result["baseline_m"].get<double>(), set_->rig.cam0_from_cam1.translation.norm(),
              5e-4);
}

TEST_F(RelposeJob, CancellationStopsTheJob) {
  JobContext context = Context();
  context.progress.is_cancelled = [] { return true; };
  EXPECT_THROW(RunRelativePoseJob({{"board", Board()},
                                   {"calibrations", {{"cam0", "truth0"}, {"cam1", "truth1"}}}},
                                  context),
               Cancelled);
}

}  // namespace
}  // namespace omnirig::api
