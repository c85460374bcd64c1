#include "api/slam_job.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "api/camera_json.h"
#include "engine/util/check.h"
#include "testing/geometry/test_rig.h"

namespace omnirig::api {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class TempDataset : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("omnirig_slam_json_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "cam0");
    fs::create_directories(dir_ / "cam1");
  }
  void TearDown() override { fs::remove_all(dir_); }
  void WriteImage(const std::string& name, int width, int height, int grey = 0) {
    cv::imwrite((dir_ / name).string(), cv::Mat(height, width, CV_8UC3, cv::Scalar::all(grey)));
    names_.push_back(name);
    std::sort(names_.begin(), names_.end());
  }
  std::string ExpectInvalid(const std::function<void()>& f) {
    try {
      f();
    } catch (const InvalidArgument& e) {
      return e.what();
    }
    ADD_FAILURE() << "expected InvalidArgument";
    return "";
  }
  fs::path dir_;
  std::vector<std::string> names_;
};

TEST(SlamOptionsFromJson, ReadsFieldsAndRefusesUnknownOrInvalidOnes) {
  const slam::SlamOptions options =
      SlamOptionsFromJson({{"max_features", 500}, {"local_window_frames", 3}, {"seed", 7}});
  EXPECT_EQ(options.features.max_features, 500);
  EXPECT_EQ(options.local_window_frames, 3);
  EXPECT_EQ(options.essential.seed, 7u);
  try {
    SlamOptionsFromJson({{"max_feature", 500}});
    FAIL();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("options.max_feature"), std::string::npos);
  }
  EXPECT_THROW(SlamOptionsFromJson({{"detection_scale", 2.0}}), InvalidArgument);
  EXPECT_THROW(SlamOptionsFromJson({{"min_matches", "many"}}), InvalidArgument);
}

TEST(SlamOptionsFromJson, ReadsTheCalibrationRefinement) {
  using slam::CalibrationRefinement;
  EXPECT_EQ(slam::SlamOptions().calibration_refinement.refine, CalibrationRefinement::kNone);
  EXPECT_EQ(SlamOptionsFromJson({{"refine_calibration", "intrinsics"}}).calibration_refinement.refine,
            CalibrationRefinement::kIntrinsics);
  EXPECT_EQ(SlamOptionsFromJson({{"refine_calibration", "rig"}}).calibration_refinement.refine,
            CalibrationRefinement::kRig);
  EXPECT_EQ(SlamOptionsFromJson({{"refine_calibration", true}}).calibration_refinement.refine,
            CalibrationRefinement::kAll);
  EXPECT_EQ(SlamOptionsFromJson({{"refine_calibration", false}}).calibration_refinement.refine,
            CalibrationRefinement::kNone);
  const slam::SlamOptions fixed = SlamOptionsFromJson(
      {{"refine_calibration", "all"}, {"fixed_intrinsics", {"xi", "alpha", "k5", "gamma"}}});
  EXPECT_TRUE(fixed.calibration_refinement.fixed_intrinsics[UnifiedIntrinsics::kGammaV]);
  EXPECT_FALSE(fixed.calibration_refinement.fixed_intrinsics[UnifiedIntrinsics::kK3]);
  auto message = [](const json& options) {
    try {
      SlamOptionsFromJson(options);
    } catch (const InvalidArgument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(message({{"refine_calibration", "focal"}}).find("options.refine_calibration"),
            std::string::npos);
  EXPECT_NE(message({{"refine_calibration", 1}}).find("options.refine_calibration"),
            std::string::npos);
  EXPECT_NE(message({{"fixed_intrinsics", {"focal"}}}).find("options.fixed_intrinsics"),
            std::string::npos);
  EXPECT_NE(message({{"refine_calibration", "all"}, {"global_bundle_adjustment", false}})
                .find("global bundle adjustment"),
            std::string::npos);
  EXPECT_NE(message({{"refine_calibration", "intrinsics"},
                     {"fixed_intrinsics", {"xi", "gamma", "principal_point", "alpha", "k1",
                                           "k2", "k3", "k4", "k5"}}})
                .find("free intrinsic"),
            std::string::npos);
}

TEST(SlamParamsFromJson, NeedsARigJob) {
  EXPECT_EQ(SlamParamsFromJson({{"rig", "job-1"}}).rig_job, "job-1");
  EXPECT_THROW(SlamParamsFromJson(json::object()), InvalidArgument);
  EXPECT_THROW(SlamParamsFromJson({{"rig", 3}}), InvalidArgument);
  EXPECT_THROW(SlamParamsFromJson({{"rig", "a"}, {"extra", 1}}), InvalidArgument);
  EXPECT_THROW(SlamParamsFromJson({{"rig", "a"}, {"ground_truth", "../etc/passwd"}}),
               InvalidArgument);
  EXPECT_EQ(*SlamParamsFromJson({{"rig", "a"}, {"ground_truth", "gt.tum"}}).ground_truth, "gt.tum");
}

// Images of another size than the rig's calibration (a pair of other sizes, a rig calibrated for
// other images) are refused at submission from the sizes the upload's header check stored, and
// by the tracker at the frame where a run meets them (`omnirig slam DIR` has no submission).
TEST_F(TempDataset, RefusesImagesOfAnotherSizeThanTheRig) {
  const struct {
    std::vector<std::pair<std::string, int>> images;  // name, width (all 48 px high)
    int rig_width, rig_height;
    std::string at_submission, at_run;
  } cases[] = {
      {{{"cam0/a.png", 64}, {"cam1/a.png", 64}, {"cam0/b.jpg", 64}, {"cam1/b.jpg", 80}},
       64,
       48,
       "cam1/b.jpg is 80x48",
       "frame b.jpg: cam1 image is 80x48"},
      {{{"cam0/a.png", 64}, {"cam1/a.png", 64}},
       1024,
       768,
       "calibrated for 1024x768",
       "calibration is 1024x768"},
  };
  for (const auto& c : cases) {
    names_.clear();
    const StereoRig rig = TinyTestRig(c.rig_width, c.rig_height);
    SubmissionInputs inputs{
        "dataset-1", dir_, {}, [&](const std::string&) { return RigToJson(rig); }, {}};
    for (const auto& [name, width] : c.images) {
      WriteImage(name, width, 48);
      inputs.images.push_back({name, width, 48});
    }
    const std::string refused = ExpectInvalid([&] { CheckSlamInputs({{"rig", "r"}}, inputs); });
    EXPECT_NE(refused.find(c.at_submission), std::string::npos) << refused;
    const std::string failed = ExpectInvalid([&] {
      RunSlamOnDataset(rig, dir_, names_, slam::SlamOptions(), std::nullopt, dir_ / "out",
                       ProgressSink(), nullptr);
    });
    EXPECT_NE(failed.find(c.at_run), std::string::npos) << failed;
  }
}

TEST_F(TempDataset, RefusesAtSubmissionWhatTheJobWouldFailOnAtItsStart) {
  const StereoRig rig = TinyTestRig(64, 48);
  SubmissionInputs inputs{"dataset-1", dir_, {}, [&](const std::string&) { return RigToJson(rig); },
                          {}};
  WriteImage("cam0/a.png", 64, 48);
  inputs.images.push_back({"cam0/a.png", 64, 48});
  // Images of one camera only.
  std::string refused = ExpectInvalid([&] { CheckSlamInputs({{"rig", "r"}}, inputs); });
  EXPECT_NE(refused.find("stereo frames"), std::string::npos) << refused;
  EXPECT_NE(refused.find("0 cam1/ images"), std::string::npos) << refused;

  WriteImage("cam1/a.png", 64, 48);
  inputs.images.push_back({"cam1/a.png", 64, 48});
  EXPECT_NO_THROW(CheckSlamInputs({{"rig", "r"}}, inputs));
  // A ground truth that is not there: the error lists the ones there are.
  refused = ExpectInvalid(
      [&] { CheckSlamInputs({{"rig", "r"}, {"ground_truth", "ground_truth.tum"}}, inputs); });
  EXPECT_NE(refused.find("holds no .tum file"), std::string::npos) << refused;
  std::ofstream(dir_ / "trajectory.tum") << "0 0 0 0 0 0 0 1\n";
  refused = ExpectInvalid(
      [&] { CheckSlamInputs({{"rig", "r"}, {"ground_truth", "ground_truth.tum"}}, inputs); });
  EXPECT_NE(refused.find("its .tum files: trajectory.tum"), std::string::npos) << refused;
  EXPECT_NO_THROW(CheckSlamInputs({{"rig", "r"}, {"ground_truth", "trajectory.tum"}}, inputs));
  // No rig: the message names the job type that makes one.
  refused = ExpectInvalid([&] { SlamParamsFromJson(json::object()); });
  EXPECT_NE(refused.find("relative_pose job"), std::string::npos) << refused;
}

TEST_F(TempDataset, RefusesAGroundTruthOfTheWrongLengthBeforeWork) {
  WriteImage("cam0/a.png", 64, 48);
  WriteImage("cam1/a.png", 64, 48);
  std::ofstream(dir_ / "gt.tum") << "0 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n";
  const std::string message = ExpectInvalid([&] {
    RunSlamOnDataset(TinyTestRig(64, 48), dir_, names_, slam::SlamOptions(), dir_ / "gt.tum",
                     dir_ / "out", ProgressSink(), nullptr);
  });
  EXPECT_NE(message.find("2 poses but the sequence has 1"), std::string::npos) << message;
  EXPECT_FALSE(fs::exists(dir_ / "out" / "map.ply"));
}

TEST_F(TempDataset, BlackFramesAreReportedLostNotFatal) {
  for (const char* name : {"a.png", "b.png", "c.png"}) {
    WriteImage(std::string("cam0/") + name, 64, 48);
    WriteImage(std::string("cam1/") + name, 64, 48);
  }
  std::vector<double> fractions;
  const ProgressSink progress{[&](double f, const std::string&, const std::string&) {
                                fractions.push_back(f);
                              },
                              nullptr};
  const json result = RunSlamOnDataset(TinyTestRig(64, 48), dir_, names_, slam::SlamOptions(),
                                       std::nullopt, dir_ / "out", progress, nullptr);
  EXPECT_EQ(result["num_frames"], 3);
  EXPECT_EQ(result["num_tracked"], 0);
  for (const json& frame : result["frames"]) {
    EXPECT_EQ(frame["state"], "lost");
    EXPECT_NE(frame["reason"].get<std::string>().find("black"), std::string::npos);
    EXPECT_TRUE(frame["world_from_rig"].is_null());
  }
  EXPECT_TRUE(fs::exists(dir_ / "out" / "trajectory.json"));
  EXPECT_TRUE(fs::exists(dir_ / "out" / "map.ply"));
  ASSERT_FALSE(fractions.empty());
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  EXPECT_DOUBLE_EQ(fractions.back(), 1.0);
  EXPECT_TRUE(result["calibration_refinement"].is_null());  // not asked for
}

TEST_F(TempDataset, ARefinementThatCannotRunSaysWhy) {
  for (const char* name : {"a.png", "b.png"}) {
    WriteImage(std::string("cam0/") + name, 64, 48);
    WriteImage(std::string("cam1/") + name, 64, 48);
  }
  slam::SlamOptions options;
  options.calibration_refinement.refine = slam::CalibrationRefinement::kIntrinsics;
  const json result = RunSlamOnDataset(TinyTestRig(64, 48), dir_, names_, options, std::nullopt,
                                       dir_ / "out", ProgressSink(), nullptr);
  const json& refinement = result["calibration_refinement"];
  ASSERT_TRUE(refinement.is_object());
  EXPECT_EQ(refinement["refine"], "intrinsics");
  EXPECT_FALSE(refinement["applied"].get<bool>());
  EXPECT_NE(refinement["reason"].get<std::string>().find("0 tracked frame"), std::string::npos)
      << refinement["reason"];
  EXPECT_EQ(refinement["before"], refinement["after"]);
  EXPECT_EQ(refinement["after"]["cameras"]["cam0"]["intrinsics"]["gamma_u"], 0.3 * 48);
}

// Frame selection: frame_step on an image sequence keeps every n-th pair and its ground-truth
// pose; on a recording, the time range selects frames by container time and the ground truth is
// matched to them by timestamp (a missing pose is named).
TEST_F(TempDataset, FrameSelectionOnImagesAndVideos) {
  slam::VideoFrameOptions every_second, time_range;
  every_second.frame_step = 2;
  time_range.start_s = 0.15;
  time_range.end_s = 0.45;
  const struct {
    const char* kind;
    slam::VideoFrameOptions frames;
    double gt_first_s, gt_step_s;    // the ground truth's timestamps, one per pair
    std::vector<std::string> names;  // of the frames kept
    double last_timestamp_s;         // the last kept frame's, in trajectory.json
  } cases[] = {
      {"images", every_second, 10.0, 1.0, {"a.png", "c.png", "e.png"}, 14.0},
      {"video_pair", time_range, 0.0, 0.1, {"t000000.200", "t000000.300", "t000000.400"}, 0.4},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.kind);
    names_.clear();
    const bool video = std::string(c.kind) == "video_pair";
    if (video) {
      for (const char* name : {"cam0.mkv", "cam1.mkv"}) {
        cv::VideoWriter writer((dir_ / name).string(), cv::CAP_FFMPEG,
                               cv::VideoWriter::fourcc('F', 'F', 'V', '1'), 10.0, cv::Size(64, 48));
        for (int i = 0; i < 6; ++i) writer.write(cv::Mat(48, 64, CV_8UC3, cv::Scalar::all(0)));
        names_.push_back(name);
      }
    } else {
      for (const char* name : {"a.png", "b.png", "c.png", "d.png", "e.png", "f.png"}) {
        WriteImage(std::string("cam0/") + name, 64, 48);
        WriteImage(std::string("cam1/") + name, 64, 48);
      }
    }
    std::ofstream gt(dir_ / "gt.tum");
    for (int i = 0; i < 6; ++i)
      gt << c.gt_first_s + c.gt_step_s * i << " " << i << " 0 0 0 0 0 1\n";
    gt.close();
    const fs::path out = dir_ / c.kind;
    const json result =
        RunSlamOnDataset(TinyTestRig(64, 48), dir_, names_, slam::SlamOptions(), dir_ / "gt.tum",
                         out, ProgressSink(), nullptr, std::nullopt, c.frames);
    ASSERT_EQ(result["num_frames"], 3);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(result["frames"][k]["name"], c.names[k]);
    EXPECT_EQ(result["input"]["kind"], c.kind);
    std::ifstream file(out / "trajectory.json");
    EXPECT_NEAR(json::parse(file)["frames"][2]["timestamp_s"].get<double>(), c.last_timestamp_s,
                1e-9);
    if (!video) {
      EXPECT_EQ(result["input"]["num_image_pairs"], 6);
      continue;
    }
    EXPECT_EQ(result["input"]["codec"], "FFV1");
    std::ofstream(dir_ / "gt.tum") << "0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 1\n";
    const std::string message = ExpectInvalid([&] {
      RunSlamOnDataset(TinyTestRig(64, 48), dir_, names_, slam::SlamOptions(), dir_ / "gt.tum",
                       dir_ / "out2", ProgressSink(), nullptr, std::nullopt, c.frames);
    });
    EXPECT_NE(message.find("no pose within 25 ms of the frame at 0.2 s"), std::string::npos)
        << message;
  }
}

TEST(SlamJobType, IsRegisteredAndValidates) {
  const JobType job_type = SlamJobType();
  EXPECT_EQ(job_type.name, "slam");
  const JobType* type = &job_type;
  EXPECT_THROW(type->validate(json::object()), InvalidArgument);
  EXPECT_EQ(type->referenced_jobs({{"rig", "r1"}}),
            (std::vector<JobReference>{{"r1", "relative_pose", "rig"}}));
}

// The frame selection params: parsed, checked, and named when wrong.
TEST(SlamParams, FrameSelection) {
  const SlamParams parsed = SlamParamsFromJson({{"rig", "r"},
                                                {"frame_step", 3},
                                                {"start_s", 1.5},
                                                {"end_s", 4},
                                                {"pair_tolerance_s", 0.002}});
  EXPECT_EQ(parsed.frames.frame_step, 3);
  EXPECT_EQ(parsed.frames.start_s, 1.5);
  EXPECT_EQ(parsed.frames.end_s, 4.0);
  EXPECT_EQ(parsed.frames.pair_tolerance_s, 0.002);
  EXPECT_TRUE(parsed.video_only_fields);
  EXPECT_FALSE(SlamParamsFromJson({{"rig", "r"}, {"frame_step", 2}}).video_only_fields);
  for (const json& bad : {json{{"frame_step", 0}}, json{{"frame_step", 1.5}},
                          json{{"start_s", "1"}}, json{{"start_s", 5}, {"end_s", 2}}}) {
    json params = bad;
    params["rig"] = "r";
    EXPECT_THROW(SlamParamsFromJson(params), InvalidArgument) << bad;
  }
}

// Which files make a recording, and which mixtures are refused.
TEST(FindStereoVideos, PairStackedAndAmbiguity) {
  const fs::path dir = "/data";
  EXPECT_FALSE(FindStereoVideos(dir, {"cam0/a.png", "cam1/a.png", "gt.tum"}));
  const auto pair = FindStereoVideos(dir, {"CAM0.MP4", "cam1.mkv", "gt.tum"});
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->cam0, dir / "CAM0.MP4");
  EXPECT_EQ(pair->cam1, dir / "cam1.mkv");
  const auto stacked = FindStereoVideos(dir, {"stacked.avi", "notes.mp4"});
  ASSERT_TRUE(stacked);
  EXPECT_TRUE(stacked->stacked());
  EXPECT_THROW(FindStereoVideos(dir, {"cam0.mp4", "cam0.mkv", "cam1.mp4"}), InvalidArgument);
  EXPECT_THROW(FindStereoVideos(dir, {"cam0.mp4"}), InvalidArgument);
  EXPECT_THROW(FindStereoVideos(dir, {"cam0.mp4", "cam1.mp4", "stacked.mp4"}), InvalidArgument);
  EXPECT_THROW(FindStereoVideos(dir, {"cam0.mp4", "cam1.mp4", "cam0/a.png"}), InvalidArgument);
}

}  // namespace
}  // namespace omnirig::api
