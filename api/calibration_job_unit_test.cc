#include "api/calibration_job.h"

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <unistd.h>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "api/board_json.h"
#include "api/camera_json.h"
#include "api/job_types.h"
#include "testing/calib/model_import.h"
#include "testing/calib/synthetic_corners.h"

namespace omnirig::api {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json ValidParams() {
  return {{"board", {{"type", "checkerboard"}, {"cols", 8}, {"rows", 6}, {"square_size_mm", 40}}}};
}

// The message of the InvalidArgument that validating `params` throws ("" when none).
std::string ValidationError(const json& params) {
  try {
    CalibrationRequestFromJson(params);
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "";
}

TEST(CalibrationJson, ParsesBoardOptionsAndHints) {
  json params = ValidParams();
  params["options"] = {{"fix", {"xi", "tangential"}}, {"free", {"k5"}},
                       {"huber_loss_px", 2.0},        {"principal_point_px", {320, 240}},
                       {"redetect", false},           {"allow_exhaustive", true},
                       {"max_num_iterations", 50}, {"max_views", 40}};
  params["hints"] = {{"a.png", {{1, 2}, {3, 4}, {5, 6}, {7, 8}}}};
  const CalibrationRequest request = CalibrationRequestFromJson(params);
  EXPECT_EQ(request.board.cols, 8);
  EXPECT_DOUBLE_EQ(request.board.square_size_m, 0.04);
  const auto& fixed = request.options.calibrate.fixed;
  EXPECT_TRUE(fixed[UnifiedIntrinsics::kXi]);
  EXPECT_TRUE(fixed[UnifiedIntrinsics::kK3]);
  EXPECT_FALSE(fixed[UnifiedIntrinsics::kK5]);
  EXPECT_TRUE(fixed[UnifiedIntrinsics::kAlpha]);  // default
  EXPECT_EQ(request.options.calibrate.huber_loss_px, 2.0);
  EXPECT_FALSE(request.options.redetect_with_model);
  EXPECT_TRUE(request.options.detect.allow_exhaustive);
  EXPECT_TRUE(request.options.detect.refine_subpixel);  // default
  EXPECT_EQ(request.options.calibrate.max_num_iterations, 50);
  EXPECT_EQ(request.options.selection.max_views, 40);
  EXPECT_EQ(CalibrationRequestFromJson(ValidParams()).options.selection.max_views, 50);
  params["options"] = {{"max_views", 2}};
  EXPECT_THROW(CalibrationRequestFromJson(params), InvalidArgument);  // 0 or at least 3
  params["options"] = {{"max_views", 40}};
  EXPECT_FALSE(request.options.svp);
  ASSERT_EQ(request.options.hints.count("a.png"), 1u);
  EXPECT_EQ(request.options.hints.at("a.png")[3], Eigen::Vector2d(7, 8));
}

TEST(CalibrationJson, ParsesTheSvpCheck) {
  json params = ValidParams();
  params["svp"] = {{"mirror", {{"rim_radius_mm", 30}, {"rim_height_mm", 12.5}}},
                   {"image", "b.png"},
                   {"search_margin_px", 25}};
  const CalibrationRequest request = CalibrationRequestFromJson(params);
  ASSERT_TRUE(request.options.svp);
  ASSERT_TRUE(request.options.svp->mirror);
  EXPECT_DOUBLE_EQ(request.options.svp->mirror->rim_radius_m, 0.03);
  EXPECT_DOUBLE_EQ(request.options.svp->mirror->rim_height_m, 0.0125);
  EXPECT_EQ(request.options.svp->image, "b.png");
  EXPECT_DOUBLE_EQ(request.options.svp->check.search_margin_px, 25.0);
  params["svp"] = json::object();
  const CalibrationRequest rim_only = CalibrationRequestFromJson(params);
  ASSERT_TRUE(rim_only.options.svp);
  EXPECT_FALSE(rim_only.options.svp->mirror);
}

TEST(CalibrationJson, ValidationNamesTheField) {
  EXPECT_NE(ValidationError(json::object()).find("'params.board'"), std::string::npos);
  json params = ValidParams();
  params["board"]["colz"] = 3;
  EXPECT_NE(ValidationError(params).find("board.colz"), std::string::npos);
  params = ValidParams();
  params["board"]["cols"] = "8";
  EXPECT_NE(ValidationError(params).find("board.cols"), std::string::npos);
  params = ValidParams();
  params["board"]["square_size_mm"] = 4e6;
  EXPECT_NE(ValidationError(params).find("square size"), std::string::npos);
  params = ValidParams();
  params["board"]["type"] = "circles";
  EXPECT_NE(ValidationError(params).find("board.type"), std::string::npos);
  params = ValidParams();
  params["board"]["type"] = "charuco";
  EXPECT_NE(ValidationError(params).find("board.marker_size_mm"), std::string::npos);
  params = ValidParams();
  params["options"] = {{"fix", {"k9"}}};
  EXPECT_NE(ValidationError(params).find("options.fix"), std::string::npos);
  params = ValidParams();
  params["options"] = {{"max_num_iterations", 1.5}};
  EXPECT_NE(ValidationError(params).find("options.max_num_iterations"), std::string::npos);
  params = ValidParams();
  params["options"] = {{"speed", "fast"}};
  EXPECT_NE(ValidationError(params).find("options.speed"), std::string::npos);
  params = ValidParams();
  params["hints"] = {{"a.png", {{1, 2}, {3, 4}}}};
  EXPECT_NE(ValidationError(params).find("hints.a.png"), std::string::npos);
  params = ValidParams();
  params["svp"] = {{"mirror", {{"rim_radius_mm", 30}}}};
  EXPECT_NE(ValidationError(params).find("svp.mirror.rim_height_mm"), std::string::npos);
  params["svp"] = {{"mirror", {{"rim_radius_mm", -3}, {"rim_height_mm", 10}}}};
  EXPECT_NE(ValidationError(params).find("field 'svp'"), std::string::npos);
  params["svp"] = {{"margin", 3}};
  EXPECT_NE(ValidationError(params).find("svp.margin"), std::string::npos);
  params = ValidParams();
  params["extra"] = 1;
  EXPECT_NE(ValidationError(params).find("params.extra"), std::string::npos);
  EXPECT_EQ(ValidationError(ValidParams()), "");
}

TEST(CalibrationJson, KalibrsAprilgridAndTargetFiles) {
  json params = {{"board",
                  {{"type", "aprilgrid"},
                   {"tag_cols", 6},
                   {"tag_rows", 6},
                   {"tag_size_m", 0.088},
                   {"tag_spacing", 0.3}}}};
  const CalibrationRequest grid = CalibrationRequestFromJson(params);
  EXPECT_EQ(grid.board.type, BoardSpec::Type::kAprilgrid);
  EXPECT_EQ(grid.board.cols, 12);
  EXPECT_DOUBLE_EQ(grid.board.square_size_m, 0.088);
  params["board"]["tag_spacing"] = 0.0;
  EXPECT_NE(ValidationError(params).find("tag spacing"), std::string::npos);
  params["board"].erase("tag_spacing");
  EXPECT_NE(ValidationError(params).find("board.tag_spacing"), std::string::npos);
  params["board"]["tag_spacing"] = 0.3;
  params["board"]["square_size_mm"] = 30;
  EXPECT_NE(ValidationError(params).find("board.square_size_mm"), std::string::npos);

  // A Kalibr target file of the dataset in place of the object: read when the job runs.
  const CalibrationRequest named = CalibrationRequestFromJson({{"board", "april_6x6.yaml"}});
  EXPECT_EQ(named.kalibr_target_file, "april_6x6.yaml");
  EXPECT_NE(ValidationError({{"board", "board.txt"}}).find(".yaml"), std::string::npos);
  EXPECT_NE(ValidationError({{"board", "../april.yaml"}}).find(".yaml"), std::string::npos);
  EXPECT_NE(ValidationError({{"board", 5}}).find("'params.board'"), std::string::npos);

  // At submission the file must be in the dataset; the message lists the .yaml files there.
  const JobType type = CalibrationJobType();
  SubmissionInputs inputs;
  inputs.images = {{"a.png", 640, 480}, {"target.yaml", 0, 0}};
  try {
    type.check_inputs({{"board", "april_6x6.yaml"}}, inputs);
    ADD_FAILURE() << "a missing target file was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("its .yaml files: target.yaml"), std::string::npos)
        << e.what();
  }
  EXPECT_NO_THROW(type.check_inputs({{"board", "target.yaml"}}, inputs));
  // The target file and a trajectory are not images of the board.
  EXPECT_EQ(CalibrationImageNames(std::nullopt, {"a.png", "target.yaml", "run.tum"}),
            std::vector<std::string>{"a.png"});
}

TEST(CalibrationJson, ReadsTheKalibrTargetWhenTheJobRuns) {
  const fs::path dir = fs::temp_directory_path() / ("omnirig_target_" + std::to_string(getpid()));
  fs::create_directories(dir);
  std::ofstream(dir / "april.yaml") << "target_type: 'aprilgrid'\ntagCols: 4\ntagRows: 3\n"
                                       "tagSize: 0.05\ntagSpacing: 0.25\n";
  std::ofstream(dir / "broken.yaml") << "target_type: 'aprilgrid'\ntagCols: 4\n";
  const BoardSpec board = ReadKalibrTargetFile(dir, "april.yaml");
  EXPECT_EQ(board.type, BoardSpec::Type::kAprilgrid);
  EXPECT_EQ(board.rows, 6);
  EXPECT_DOUBLE_EQ(board.tag_spacing, 0.25);
  try {
    ReadKalibrTargetFile(dir, "broken.yaml");
    ADD_FAILURE() << "an incomplete target was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("board 'broken.yaml': Kalibr target: missing key"),
              std::string::npos)
        << e.what();
  }
  fs::remove_all(dir);
}

TEST(CalibrationJson, OneCameraOfAStereoDataset) {
  json params = ValidParams();
  params["camera"] = "cam2";
  EXPECT_NE(ValidationError(params).find("'params.camera'"), std::string::npos);
  params["camera"] = "cam1";
  const CalibrationRequest request = CalibrationRequestFromJson(params);
  ASSERT_TRUE(request.camera.has_value());
  const std::vector<std::string> stereo = {"cam0/a.png", "cam0/b.png", "cam1/a.png"};
  EXPECT_EQ(CalibrationImageNames(request.camera, stereo), std::vector<std::string>{"cam1/a.png"});
  EXPECT_EQ(CalibrationImageNames(std::string("cam0"), stereo).size(), 2u);
  // Both cameras' images as one camera: refused, naming "camera".
  try {
    CalibrationImageNames(std::nullopt, stereo);
    ADD_FAILURE() << "two cameras' images were taken for one";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("\"camera\""), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("2 in cam0/, 1 in cam1/"), std::string::npos) << e.what();
  }
  EXPECT_THROW(CalibrationImageNames(std::string("cam1"), {"cam0/a.png"}), InvalidArgument);
  // A mono dataset (any folder layout but both camN/) is taken whole.
  const std::vector<std::string> mono = {"a.png", "cam0/b.png"};
  EXPECT_EQ(CalibrationImageNames(std::nullopt, mono), mono);
}

TEST(CalibrationJson, ResultHasTheIssuesKeys) {
  CameraModel camera;
  camera.width = 1024;
  camera.height = 768;
  camera.intrinsics.params = {0.9, 300, 300, 512, 384, 0, -0.1, 0.02, 0, 0, 0};
  const BoardSpec board = SyntheticBoard();
  SyntheticCornerOptions synth;
  synth.num_views = 6;
  synth.noise_px = 0.1;
  std::vector<CalibrationView> views = MakeSyntheticCornerSet(camera, board, synth).views;
  views.push_back({"missing.png", {}});
  views.back().detection.reason = "no checkerboard 8x6 (40 mm) found";
  CalibrationReport report =
      Calibrate(views, camera.width, camera.height, board, CalibrationOptions(), {});
  const json result = CalibrationReportToJson(report);
  EXPECT_FALSE(result.contains("svp"));  // only when asked for
  report.svp.emplace();
  report.svp->predicted_circle_px = Eigen::Vector3d(510, 380, 300);
  report.svp->found_circle_px = Eigen::Vector3d(512, 381, 302);
  report.svp->centre_offset_px = std::hypot(2.0, 1.0);
  report.svp->radius_offset_px = 2.0;
  report.svp_image = "view0";
  const json svp = CalibrationReportToJson(report)["svp"];
  EXPECT_TRUE(svp["found"].get<bool>());
  EXPECT_EQ(svp["found_circle_px"], json({512.0, 381.0, 302.0}));
  EXPECT_EQ(svp["predicted_circle_px"], json({510.0, 380.0, 300.0}));
  EXPECT_DOUBLE_EQ(svp["radius_offset_px"].get<double>(), 2.0);
  EXPECT_EQ(svp["image"], "view0");
  EXPECT_EQ(svp["overlay"], "svp_overlay.png");
  EXPECT_EQ(result["camera"]["model"], "unified");
  EXPECT_EQ(result["camera"]["image_size"], json({1024, 768}));
  for (const char* name : UnifiedIntrinsics::kNames) {
    EXPECT_TRUE(result["camera"]["intrinsics"].contains(name)) << name;
    EXPECT_TRUE(result["camera"]["intrinsics_std"].contains(name)) << name;
  }
  for (const char* key : {"rms_px", "mean_px", "std_px", "images", "solver"}) {
    EXPECT_TRUE(result.contains(key)) << key;
  }
  ASSERT_EQ(result["images"].size(), 7u);
  const json& used = result["images"][0];
  EXPECT_EQ(used["name"], "view0");
  EXPECT_TRUE(used["used"].get<bool>());
  EXPECT_EQ(used["cam_from_board"]["rotation_wxyz"].size(), 4u);
  EXPECT_EQ(used["cam_from_board"]["translation_m"].size(), 3u);
  const json& unused = result["images"][6];
  EXPECT_FALSE(unused["used"].get<bool>());
  EXPECT_EQ(unused["reason"], "no checkerboard 8x6 (40 mm) found");
  EXPECT_TRUE(unused["cam_from_board"].is_null());
  EXPECT_EQ(result["solver"]["termination"], "CONVERGENCE");
  // What became of every frame: none listed when the report has none; a long input's reasons.
  EXPECT_TRUE(result["frames"].empty());
  EXPECT_TRUE(result["frame_selection"]["max_views"].is_null());
  report.max_views = 40;
  report.frames = {{"t0.msg", false, "no_board", "", ""},
                   {"t1.msg", true, "used", "", ""},
                   {"t2.msg", false, "near_duplicate_of", "t1.msg", ""},
                   {"t3.msg", false, "detection_failed", "", "no checkerboard 8x6 found"}};
  const json with_frames = CalibrationReportToJson(report);
  ASSERT_EQ(with_frames["frames"].size(), 4u);
  EXPECT_EQ(with_frames["frames"][0], json({{"name", "t0.msg"}, {"used", false},
                                            {"reason", "no_board"}}));
  EXPECT_TRUE(with_frames["frames"][1]["used"].get<bool>());
  EXPECT_EQ(with_frames["frames"][2]["duplicate_of"], "t1.msg");
  EXPECT_EQ(with_frames["frames"][3]["detail"], "no checkerboard 8x6 found");
  EXPECT_EQ(with_frames["frame_selection"]["max_views"], 40);
  EXPECT_EQ(with_frames["frame_selection"]["num_frames"], 4);
  EXPECT_EQ(with_frames["frame_selection"]["reasons"]["used"], 1);
  EXPECT_EQ(with_frames["images"], result["images"]);  // the existing fields unchanged
  // The camera part reads back with the shared camera JSON.
  EXPECT_NEAR(CameraFromJson(result["camera"]).intrinsics.u0(),
              result["camera"]["intrinsics"]["u0"].get<double>(), 0.0);
}

TEST(CalibrationJob, IsRegisteredAndFailsClearlyOnUnusableImages) {
  const JobType job_type = CalibrationJobType();
  EXPECT_EQ(job_type.name, "calibration");
  const JobType* type = &job_type;
  EXPECT_THROW(type->validate(json::object()), InvalidArgument);
  EXPECT_FALSE(type->referenced_jobs);  // it reads no other job

  const fs::path dir =
      fs::temp_directory_path() / ("omnirig_calib_job_" + std::to_string(::getpid()));
  fs::create_directories(dir / "out");
  cv::imwrite((dir / "blank.png").string(), cv::Mat(240, 320, CV_8UC1, cv::Scalar(128)));
  std::ofstream((dir / "truncated.jpg").string()) << "\xff\xd8\xff\xe0 not really a jpeg";
  JobContext context;
  context.dataset_dir = dir;
  context.image_names = {"blank.png", "truncated.jpg"};
  context.output_dir = dir / "out";
  int detect_reports = 0;
  context.progress.report = [&](double, const std::string& stage, const std::string&) {
    detect_reports += stage == "detect";
  };
  try {
    type->run(ValidParams(), context);
    FAIL() << "expected InvalidArgument";
  } catch (const InvalidArgument& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("blank.png: no checkerboard 8x6"), std::string::npos) << message;
    EXPECT_NE(message.find("truncated.jpg: cannot read the image"), std::string::npos) << message;
  }
  EXPECT_EQ(detect_reports, 2);  // one per image, readable or not
  fs::remove_all(dir);
}

CameraModel ExportCamera() {
  CameraModel camera;
  camera.width = 1280;
  camera.height = 1024;
  camera.intrinsics.params = {1.02, 405.5, 406.25, 641.5, 509.75, 0.0,
                              -0.11, 0.013, 1.5e-3, -7.5e-4, 0.0};
  return camera;
}

TEST(CalibrationExports, OpenCvAndKalibrFilesReadBack) {
  const fs::path dir =
      fs::temp_directory_path() / ("omnirig_calib_exports_" + std::to_string(::getpid()));
  const CameraModel camera = ExportCamera();
  const json exports = WriteCameraExports(camera, dir);
  EXPECT_EQ(exports["opencv_omnidir"], "camera_opencv.yaml");
  EXPECT_EQ(exports["kalibr"], "camera_kalibr.yaml");
  EXPECT_TRUE(exports["warnings"].empty());
  // OpenCV's own reader: K, D, xi and the image size as cv::omnidir uses them.
  cv::FileStorage fs_cv((dir / "camera_opencv.yaml").string(), cv::FileStorage::READ);
  ASSERT_TRUE(fs_cv.isOpened());
  cv::Mat k, d;
  fs_cv["camera_matrix"] >> k;
  fs_cv["distortion_coefficients"] >> d;
  ASSERT_EQ(k.total(), 9u);
  ASSERT_EQ(d.total(), 4u);
  const UnifiedIntrinsics& in = camera.intrinsics;
  EXPECT_DOUBLE_EQ(k.at<double>(0, 0), in.gamma_u());
  EXPECT_DOUBLE_EQ(k.at<double>(1, 1), in.gamma_v());
  EXPECT_DOUBLE_EQ(k.at<double>(0, 2), in.u0());
  EXPECT_DOUBLE_EQ(k.at<double>(1, 2), in.v0());
  EXPECT_DOUBLE_EQ(d.at<double>(0), in.k(1));
  EXPECT_DOUBLE_EQ(d.at<double>(3), in.k(4));
  EXPECT_DOUBLE_EQ(static_cast<double>(fs_cv["xi"]), in.xi());
  EXPECT_EQ(static_cast<int>(fs_cv["image_width"]), 1280);
  EXPECT_EQ(static_cast<int>(fs_cv["image_height"]), 1024);
  // Kalibr: omni-radtan, intrinsics [xi, fu, fv, pu, pv].
  std::ifstream kalibr_file(dir / "camera_kalibr.yaml");
  const std::string kalibr((std::istreambuf_iterator<char>(kalibr_file)),
                           std::istreambuf_iterator<char>());
  EXPECT_NE(kalibr.find("camera_model: omni"), std::string::npos) << kalibr;
  EXPECT_NE(kalibr.find("distortion_model: radtan"), std::string::npos) << kalibr;
  const CameraModel back = FromKalibrOmniRadtan(kalibr);
  for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
    EXPECT_DOUBLE_EQ(back.intrinsics.params[i], in.params[i]) << UnifiedIntrinsics::kNames[i];
  }
  fs::remove_all(dir);
}

TEST(CalibrationExports, RigCamchainReadsBackWithBothCameras) {
  const fs::path dir =
      fs::temp_directory_path() / ("omnirig_rig_exports_" + std::to_string(::getpid()));
  StereoRig rig;
  rig.cam0 = ExportCamera();
  rig.cam1 = ExportCamera();
  rig.cam1.intrinsics.xi() = 0.98;
  rig.cam0_from_cam1 = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.02, Eigen::Vector3d::UnitX())),
                               Eigen::Vector3d(0.001, 0.0, 0.1));
  const json exports = WriteRigExports(rig, dir);
  EXPECT_EQ(exports["kalibr_camchain"], "camchain_kalibr.yaml");
  std::ifstream file(dir / "camchain_kalibr.yaml");
  const std::string text((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  const StereoRig back = FromKalibrCamchain(text);
  EXPECT_DOUBLE_EQ(back.cam1.intrinsics.xi(), 0.98);
  EXPECT_LT((back.cam0_from_cam1.translation - rig.cam0_from_cam1.translation).norm(), 1e-12);
  EXPECT_LT(back.cam0_from_cam1.rotation.angularDistance(rig.cam0_from_cam1.rotation), 1e-12);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace omnirig::api
