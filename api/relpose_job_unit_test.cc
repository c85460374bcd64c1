#include "api/relpose_job.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "engine/util/check.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

json Board() {
  return {{"type", "checkerboard"}, {"cols", 9}, {"rows", 6}, {"square_size_mm", 24.23}};
}

// The message of the InvalidArgument that `f` throws ("" when it does not throw).
template <typename F>
std::string ErrorOf(F f) {
  try {
    f();
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "";
}

TEST(RelposeJson, ParamsParseBoardCalibrationsAndOptions) {
  const json params = {{"board", Board()},
                       {"calibrations", {{"cam0", "job-a"}, {"cam1", "job-b"}}},
                       {"intrinsics_model", "free"},
                       {"huber_loss_px", 0.5},
                       {"sync_false_alarm_rate", 0.05}};
  const RelativePoseParams parsed = RelativePoseParamsFromJson(params);
  EXPECT_EQ(parsed.board.cols, 9);
  EXPECT_EQ(parsed.board.rows, 6);
  EXPECT_NEAR(parsed.board.square_size_m, 0.02423, 1e-12);
  EXPECT_EQ(*parsed.cam0_calibration_job, "job-a");
  EXPECT_EQ(*parsed.cam1_calibration_job, "job-b");
  EXPECT_EQ(parsed.options.intrinsics_model, "free");
  EXPECT_EQ(parsed.options.relpose.huber_loss_px, 0.5);
  EXPECT_EQ(parsed.options.relpose.sync_test.false_alarm_rate, 0.05);
  EXPECT_EQ(parsed.options.relpose.fixed_intrinsics, DefaultFixedIntrinsics());
  const RelativePoseParams self_calibrating = RelativePoseParamsFromJson({{"board", Board()}});
  EXPECT_FALSE(self_calibrating.cam0_calibration_job);
}

// The intrinsics the rig refines are chosen by intrinsics_model alone: a request that names
// them another way gets an error that points to it.
TEST(RelposeJson, IntrinsicsOptionsOtherThanTheModelAreRefusedNamingIt) {
  for (const json& params :
       {json{{"board", Board()}, {"refine_intrinsics", true}},
        json{{"board", Board()}, {"fixed_intrinsics", {"alpha", "k5", "tangential"}}},
        json{{"board", Board()}, {"intrinsics_model", "free"}, {"refine_intrinsics", true}}}) {
    const std::string message = ErrorOf([&] { RelativePoseParamsFromJson(params); });
    EXPECT_NE(message.find("params.intrinsics_model"), std::string::npos) << message;
    EXPECT_NE(message.find(params.contains("fixed_intrinsics") ? "params.fixed_intrinsics"
                                                               : "params.refine_intrinsics"),
              std::string::npos)
        << message;
  }
}

// "auto" is the default (with given calibrations too: it then chooses between keeping them and
// refining them with their own views); every candidate can be named.
TEST(RelposeJson, IntrinsicsModelDefaultsAndNamedModels) {
  EXPECT_EQ(RelativePoseParamsFromJson({{"board", Board()}}).options.intrinsics_model, "auto");
  const json calibrations = {{"cam0", "a"}, {"cam1", "b"}};
  EXPECT_EQ(RelativePoseParamsFromJson({{"board", Board()}, {"calibrations", calibrations}})
                .options.intrinsics_model,
            "auto");
  for (const char* name :
       {"fixed", "tangential_fixed", "tangential_free_cam0", "tangential_free_cam1", "free"}) {
    EXPECT_EQ(RelativePoseParamsFromJson({{"board", Board()}, {"intrinsics_model", name}})
                  .options.intrinsics_model,
              name);
  }
  for (const char* name : {"fixed", "free"}) {
    EXPECT_EQ(RelativePoseParamsFromJson(
                  {{"board", Board()}, {"calibrations", calibrations}, {"intrinsics_model", name}})
                  .options.intrinsics_model,
              name);
  }
}

// The models that recalibrate a camera with k3 = k4 = 0 need the job's own calibrations.
TEST(RelposeJson, TangentialModelsNeedTheJobsOwnCalibrations) {
  for (const char* name : {"tangential_fixed", "tangential_free_cam0", "tangential_free_cam1"}) {
    EXPECT_NE(ErrorOf([name] {
                RelativePoseParamsFromJson({{"board", Board()},
                                            {"calibrations", {{"cam0", "a"}, {"cam1", "b"}}},
                                            {"intrinsics_model", name}});
              }).find("calibrate the cameras itself"),
              std::string::npos)
        << name;
  }
}

TEST(RelposeJson, IntrinsicsModelConflictsAreRefused) {
  // The message names the field and every allowed value.
  const std::string unknown = ErrorOf([] {
    RelativePoseParamsFromJson({{"board", Board()}, {"intrinsics_model", "best"}});
  });
  for (const char* expected : {"params.intrinsics_model", "auto", "fixed", "tangential_fixed",
                               "tangential_free_cam0", "tangential_free_cam1", "free", "'best'"}) {
    EXPECT_NE(unknown.find(expected), std::string::npos) << expected << " in: " << unknown;
  }
  EXPECT_NE(ErrorOf([] {
              RelativePoseParamsFromJson({{"board", Board()}, {"intrinsics_model", 1}});
            }).find("intrinsics_model"),
            std::string::npos);
}

TEST(RelposeJson, ParamsRefuseUnknownFieldsAndWrongTypesNamingTheField) {
  EXPECT_NE(ErrorOf([] { RelativePoseParamsFromJson({{"board", Board()}, {"bord", 1}}); })
                .find("params.bord"),
            std::string::npos);
  json board = Board();
  board["cols"] = "9";
  EXPECT_NE(ErrorOf([&] { RelativePoseParamsFromJson({{"board", board}}); }).find("board.cols"),
            std::string::npos);
  board = Board();
  board["colour"] = "red";
  EXPECT_NE(ErrorOf([&] { RelativePoseParamsFromJson({{"board", board}}); }).find("board.colour"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { RelativePoseParamsFromJson(json::object()); }).find("params.board"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] {
              RelativePoseParamsFromJson({{"board", Board()}, {"calibrations", {{"cam0", "a"}}}});
            }).find("calibrations.cam1"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] {
              RelativePoseParamsFromJson(
                  {{"board", Board()}, {"calibrations", {{"cam0", "a"}, {"cam1", 7}}}});
            }).find("calibrations.cam1"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] {
              RelativePoseParamsFromJson({{"board", Board()}, {"resolve_corner_order", "yes"}});
            }).find("resolve_corner_order"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] {
              RelativePoseParamsFromJson({{"board", Board()}, {"huber_loss_px", -1}});
            }).find("huber_loss_px"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] {
              RelativePoseParamsFromJson({{"board", Board()}, {"sync_false_alarm_rate", 1}});
            }).find("params.sync_false_alarm_rate"),
            std::string::npos);
  EXPECT_THROW(RelativePoseParamsFromJson(json::array()), InvalidArgument);
}

TEST(RelposeJson, JobTypeIsRegisteredAndNamesItsCalibrations) {
  const JobType job_type = RelativePoseJobType();
  EXPECT_EQ(job_type.name, "relative_pose");
  const JobType* type = &job_type;
  const json params = {{"board", Board()}, {"calibrations", {{"cam0", "c0"}, {"cam1", "c1"}}}};
  EXPECT_NO_THROW(type->validate(params));
  EXPECT_EQ(type->referenced_jobs(params),
            (std::vector<JobReference>{{"c0", "calibration", "calibrations.cam0"},
                                       {"c1", "calibration", "calibrations.cam1"}}));
  EXPECT_TRUE(type->referenced_jobs({{"board", Board()}}).empty());
  EXPECT_THROW(type->validate({{"board", Board()}, {"extra", 1}}), InvalidArgument);
}

// A Kalibr camchain of the dataset in place of two calibration jobs.
TEST(RelposeJson, CalibrationsAsAKalibrCamchainOfTheDataset) {
  const JobType type = RelativePoseJobType();
  const json params = {{"board", Board()}, {"calibrations", "camchain.yaml"}};
  EXPECT_EQ(RelativePoseParamsFromJson(params).kalibr_camchain_file, "camchain.yaml");
  EXPECT_TRUE(type.referenced_jobs(params).empty());
  EXPECT_NE(ErrorOf([&] {
              RelativePoseParamsFromJson({{"board", Board()}, {"calibrations", "chain.txt"}});
            }).find("'params.calibrations' names a Kalibr camchain"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] {
              RelativePoseParamsFromJson({{"board", Board()},
                                          {"calibrations", "camchain.yaml"},
                                          {"intrinsics_model", "tangential_fixed"}});
            }).find("intrinsics_model"),
            std::string::npos);
  SubmissionInputs inputs;
  inputs.images = {{"cam0/a.png", 640, 480}, {"cam1/a.png", 640, 480}, {"other.yaml", 0, 0}};
  EXPECT_NE(ErrorOf([&] { type.check_inputs(params, inputs); })
                .find("'params.calibrations' names 'camchain.yaml', which the dataset does not "
                      "hold (its .yaml files: other.yaml)"),
            std::string::npos);
  inputs.images.push_back({"camchain.yaml", 0, 0});
  EXPECT_NO_THROW(type.check_inputs(params, inputs));
}

TEST(RelposeJson, ResultHasTheIssueKeys) {
  RelativePoseReport report;
  report.success = true;
  report.rig.cam0_from_cam1 = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 0.1));
  report.rig.cam0.width = report.rig.cam1.width = 640;
  report.rig.cam0.height = report.rig.cam1.height = 480;
  report.baseline_m = 0.1;
  report.baseline_std_m = 1e-5;
  report.baseline_std_robust_m = 3e-5;
  report.rms_px = 0.2;
  report.pairs.resize(2);
  report.pairs[0].name = "a";
  report.pairs[0].used = true;
  report.pairs[0].rms_px = 0.19;
  report.pairs[0].num_corners = 54;
  report.pairs[0].cam1_order = 1;
  report.pairs[0].sync_statistic = 3.5;
  report.pairs[0].board_offset_m = 4e-4;
  report.pairs[0].board_rotation_deg = 0.1;
  report.pairs[1].name = "b";
  report.pairs[1].reason = "board seen by cam0 only";
  report.sync_test.run = true;
  report.sync_test.corner_noise_px = {0.12, 0.13};
  report.sync_test.limit = 21.6;
  const json camera0 = {{"model", "unified"}, {"marker", 0}};
  const json result = RelativePoseResultToJson(report, camera0, camera0, false);
  EXPECT_EQ(result["cam0_from_cam1"]["rotation_wxyz"].size(), 4u);
  EXPECT_EQ(result["cam0_from_cam1"]["translation_m"][2].get<double>(), 0.1);
  EXPECT_EQ(result["baseline_m"].get<double>(), 0.1);
  EXPECT_EQ(result["baseline_std_m"].get<double>(), 1e-5);
  EXPECT_EQ(result["baseline_std_robust_m"].get<double>(), 3e-5);
  EXPECT_TRUE(result["rotation_std_robust_deg"].is_null());  // not computed (-1)
  EXPECT_EQ(result["rms_px"].get<double>(), 0.2);
  EXPECT_EQ(result["cameras"]["cam0"], camera0);  // the calibration's own object
  ASSERT_EQ(result["pairs"].size(), 2u);
  EXPECT_EQ(result["pairs"][0]["name"], "a");
  EXPECT_TRUE(result["pairs"][0]["used"].get<bool>());
  EXPECT_EQ(result["pairs"][0]["cam1_corner_order"], 1);
  EXPECT_FALSE(result["pairs"][1]["used"].get<bool>());
  EXPECT_TRUE(result["pairs"][1]["rms_px"].is_null());
  EXPECT_EQ(result["pairs"][1]["reason"], "board seen by cam0 only");
  EXPECT_EQ(result["pairs"][0]["sync_statistic"].get<double>(), 3.5);
  EXPECT_EQ(result["pairs"][0]["board_offset_m"].get<double>(), 4e-4);
  EXPECT_TRUE(result["pairs"][1]["sync_statistic"].is_null());
  EXPECT_EQ(result["sync_test"]["corner_noise_px"][1].get<double>(), 0.13);
  EXPECT_EQ(result["sync_test"]["limit"].get<double>(), 21.6);
  // With refined intrinsics the cameras are the refined ones.
  const json refined = RelativePoseResultToJson(report, camera0, camera0, true);
  EXPECT_EQ(refined["cameras"]["cam0"]["image_size"][0], 640);
}

// A dataset folder with small images, for the checks that run before any detection.
class RelposeJobInput : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("omnirig_relpose_test_" + std::to_string(std::random_device()()));
    std::filesystem::create_directories(dir_ / "cam0");
    std::filesystem::create_directories(dir_ / "cam1");
    context_.dataset_dir = dir_;
    camera_.width = 64;
    camera_.height = 48;
    camera_.intrinsics.params = {0.9, 20, 20, 32, 24, 0, 0, 0, 0, 0, 0};
    context_.load_result = [this](const std::string& id) -> json {
      if (id == "not-a-calibration") return {{"frames", 3}};
      return {{"camera", CameraToJson(camera_)}};
    };
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  void WriteImage(const std::string& name, int width, int height) {
    cv::imwrite((dir_ / name).string(), cv::Mat(height, width, CV_8UC1, cv::Scalar(128)));
    context_.image_names.push_back(name);
  }
  json Params() const {
    return {{"board", Board()}, {"calibrations", {{"cam0", "c0"}, {"cam1", "c1"}}}};
  }

  std::filesystem::path dir_;
  JobContext context_;
  CameraModel camera_;
};

TEST_F(RelposeJobInput, ImageSizesDifferentFromTheCalibrationsAreRefused) {
  WriteImage("cam0/a.png", 64, 48);
  WriteImage("cam1/a.png", 64, 48);
  WriteImage("cam0/b.png", 64, 48);
  WriteImage("cam1/b.png", 80, 48);
  const std::string error = ErrorOf([&] { RunRelativePoseJob(Params(), context_); });
  EXPECT_NE(error.find("cam1/b.png is 80x48"), std::string::npos) << error;
  EXPECT_NE(error.find("calibration"), std::string::npos) << error;
}

TEST_F(RelposeJobInput, MissingPartnersUnreadableImagesAndWrongJobsAreRefused) {
  WriteImage("cam0/a.png", 64, 48);
  context_.image_names.push_back("cam0/z.png");
  WriteImage("cam1/a.png", 64, 48);
  EXPECT_NE(ErrorOf([&] { RunRelativePoseJob(Params(), context_); }).find("cam0/z.png"),
            std::string::npos);
  context_.image_names.erase(context_.image_names.begin() + 1);  // cam0/z.png
  std::ofstream(dir_ / "cam0/t.png") << "not an image";
  std::ofstream(dir_ / "cam1/t.png") << "not an image";
  context_.image_names.push_back("cam0/t.png");
  context_.image_names.push_back("cam1/t.png");
  EXPECT_NE(ErrorOf([&] { RunRelativePoseJob(Params(), context_); }).find("cannot be read"),
            std::string::npos);
  json params = Params();
  params["calibrations"]["cam1"] = "not-a-calibration";
  EXPECT_NE(ErrorOf([&] { RunRelativePoseJob(params, context_); }).find("not-a-calibration"),
            std::string::npos);
}

TEST_F(RelposeJobInput, NoBoardAnywhereFailsWithEachPairsReason) {
  WriteImage("cam0/a.png", 64, 48);
  WriteImage("cam1/a.png", 64, 48);
  WriteImage("cam0/b.png", 64, 48);
  WriteImage("cam1/b.png", 64, 48);
  const std::string error = ErrorOf([&] { RunRelativePoseJob(Params(), context_); });
  EXPECT_NE(error.find("too few usable pairs"), std::string::npos) << error;
  EXPECT_NE(error.find("a.png: board not found in either camera"), std::string::npos) << error;
}

}  // namespace
}  // namespace omnirig::api
