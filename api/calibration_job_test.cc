// The `calibration` job end to end on real images (skipped when ../shared/data/real is absent).

#include <cstdlib>
#include <filesystem>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <unistd.h>

#include "api/calibration_job.h"
#include "api/job_types.h"

namespace omnirig::api {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json ValidParams() {
  return {{"board", {{"type", "checkerboard"}, {"cols", 8}, {"rows", 6}, {"square_size_mm", 40}}}};
}

TEST(CalibrationJob, RunsOnTheVmrSetWithOverlays) {
  const char* source = std::getenv("OMNIRIG_SOURCE_DIR");
  const fs::path data =
      fs::path(source ? source : ".") / ".." / "shared" / "data" / "real" / "ocamcalib-vmr";
  if (!fs::is_directory(data)) GTEST_SKIP() << "real data not found at " << data;
  const fs::path out =
      fs::temp_directory_path() / ("omnirig_calib_vmr_" + std::to_string(::getpid()));
  JobContext context;
  context.dataset_dir = data;
  for (int i = 0; i < 10; ++i)
    context.image_names.push_back("VMRImage" + std::to_string(i) + ".jpg");
  context.output_dir = out;
  context.num_threads = 2;
  int solve_reports = 0;
  context.progress.report = [&](double, const std::string& stage, const std::string&) {
    solve_reports += stage == "solve";
  };
  json params = ValidParams();
  params["board"] = {{"cols", 6}, {"rows", 7}, {"square_size_mm", 30}};
  params["svp"] = json::object();  // find the rim, no mirror dimensions
  const json result = CalibrationJobType().run(params, context);
  EXPECT_EQ(result["num_views_used"], 10);
  EXPECT_LT(result["rms_px"].get<double>(), 0.5);
  EXPECT_GT(solve_reports, 3);
  // A short input: every image detected and used, no cap.
  ASSERT_EQ(result["frames"].size(), 10u);
  for (const auto& frame : result["frames"]) EXPECT_EQ(frame["reason"], "used") << frame;
  EXPECT_TRUE(result["frame_selection"]["max_views"].is_null());
  for (const auto& image : result["images"]) {
    EXPECT_TRUE(fs::exists(out / image["overlay"].get<std::string>())) << image["overlay"];
  }
  // The VMR mirror's rim is a full circle of radius ~452 px centred within ~2 px of the
  // calibrated principal point (the sensor is close to single-viewpoint).
  const json& svp = result["svp"];
  ASSERT_TRUE(svp["found"].get<bool>()) << svp.dump();
  EXPECT_EQ(svp["image"], "VMRImage0.jpg");
  EXPECT_NEAR(svp["found_circle_px"][2].get<double>(), 452.0, 5.0);
  EXPECT_LT(svp["principal_point_offset_px"].get<double>(), 5.0);
  EXPECT_TRUE(svp["predicted_circle_px"].is_null());
  EXPECT_TRUE(fs::exists(out / svp["overlay"].get<std::string>()));
  // The exports, read back with OpenCV's FileStorage: the calibrated camera.
  const json& exports = result["exports"];
  cv::FileStorage opencv((out / exports["opencv_omnidir"].get<std::string>()).string(),
                         cv::FileStorage::READ);
  ASSERT_TRUE(opencv.isOpened());
  cv::Mat k;
  opencv["camera_matrix"] >> k;
  ASSERT_EQ(k.total(), 9u);
  EXPECT_DOUBLE_EQ(k.at<double>(0, 2), result["camera"]["intrinsics"]["u0"].get<double>());
  EXPECT_DOUBLE_EQ(static_cast<double>(opencv["xi"]),
                   result["camera"]["intrinsics"]["xi"].get<double>());
  EXPECT_EQ(static_cast<int>(opencv["image_width"]), 1024);
  EXPECT_TRUE(fs::exists(out / exports["kalibr"].get<std::string>()));
  // The report of what to do next: the disk from the rim the SVP check found.
  const json& coverage = result["coverage"];
  EXPECT_EQ(coverage["disk_from"], "svp_rim");
  EXPECT_TRUE(fs::exists(out / coverage["image"].get<std::string>()));
  EXPECT_GT(coverage["covered_fraction"].get<double>(), 0.05);
  EXPECT_LT(coverage["covered_fraction"].get<double>(), 1.0);
  ASSERT_TRUE(coverage["max_uncertainty_px"].is_number()) << coverage.dump();
  EXPECT_GT(coverage["max_uncertainty_px"].get<double>(), 0.0);
  EXPECT_TRUE(fs::exists(out / coverage["uncertainty_image"].get<std::string>()));
  EXPECT_TRUE(coverage["advice"].is_array());
  // The regions and poses behind the advice, each region named by ring and clock hours.
  ASSERT_TRUE(coverage["uncovered_regions"].is_array());
  for (const json& region : coverage["uncovered_regions"]) {
    EXPECT_TRUE(region["ring"] == "inner" || region["ring"] == "middle" ||
                region["ring"] == "outer");
    EXPECT_GE(region["from_hour"].get<int>(), 1);
    EXPECT_LE(region["to_hour"].get<int>(), 12);
  }
  EXPECT_TRUE(coverage["uncertain_regions"].is_array());
  EXPECT_TRUE(coverage["uncertainty_flat"].is_boolean());
  EXPECT_TRUE(coverage["missing_poses"].is_array());
  EXPECT_GT(coverage["board_poses"]["median_distance_m"].get<double>(), 0.0);
  fs::remove_all(out);
}

}  // namespace
}  // namespace omnirig::api
