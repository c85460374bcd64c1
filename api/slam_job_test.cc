// End to end: a short synthetic stereo sequence written as a dataset, run through the `slam`
// job type, evaluated against its ground truth. Label integration (renders images).

#include <filesystem>
#include <fstream>

#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "api/slam_job.h"
#include "engine/slam/map_io.h"
#include "engine/synth/presets.h"

namespace omnirig::api {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class SlamJob : public ::testing::Test {
 protected:
  // Renders and writes the dataset once for every test of the suite.
  static void SetUpTestSuite() {
    synth::StereoSequenceOptions options;
    options.num_frames = 12;
    options.path_length_m = 1.65;  // ~20 cm steps along the curving path
    options.width = 640;
    options.height = 480;
    options.render.noise_sigma = 1.0;
    sequence_ = new synth::StereoSequence(synth::MakeStereoSequence(options));
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("omnirig_slam_job_" + std::to_string(::getpid())));
    fs::remove_all(*dir_);
    for (const char* camera : {"cam0", "cam1"}) fs::create_directories(*dir_ / "data" / camera);
    image_names_ = new std::vector<std::string>();
    std::vector<slam::StampedPose> gt;
    for (size_t i = 0; i < sequence_->names.size(); ++i) {
      for (int c = 0; c < 2; ++c) {
        const std::string name = "cam" + std::to_string(c) + "/" + sequence_->names[i] + ".png";
        cv::imwrite((*dir_ / "data" / name).string(), sequence_->images[c][i]);
        image_names_->push_back(name);
      }
      gt.push_back({sequence_->timestamps_s[i], sequence_->world_from_rig[i]});
    }
    std::sort(image_names_->begin(), image_names_->end());
    slam::WriteTum(*dir_ / "data" / "gt.tum", gt);
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete sequence_;
    delete dir_;
    delete image_names_;
  }

  void SetUp() override {
    context_.image_names = *image_names_;
    context_.job_id = "slam-test";
    context_.dataset_dir = *dir_ / "data";
    context_.output_dir = *dir_ / ("out_" + std::string(::testing::UnitTest::GetInstance()
                                                           ->current_test_info()->name()));
    context_.num_threads = 2;
    const json rig = RigToJson(sequence_->rig);
    context_.load_result = [rig](const std::string& id) {
      if (id != "rig-job") throw InvalidArgument("no job " + id);
      return rig;
    };
  }

  static synth::StereoSequence* sequence_;
  static fs::path* dir_;
  static std::vector<std::string>* image_names_;
  JobContext context_;
};

synth::StereoSequence* SlamJob::sequence_ = nullptr;
fs::path* SlamJob::dir_ = nullptr;
std::vector<std::string>* SlamJob::image_names_ = nullptr;

TEST_F(SlamJob, TracksTheSequenceWithSmallDriftAndWritesArtifacts) {
  std::vector<double> fractions;
  context_.progress.report = [&](double f, const std::string&, const std::string&) {
    fractions.push_back(f);
  };
  const JobType job_type = SlamJobType();
  EXPECT_EQ(job_type.name, "slam");
  const JobType* type = &job_type;
  const json params = {{"rig", "rig-job"}, {"ground_truth", "gt.tum"}};
  type->validate(params);
  const json result = type->run(params, context_);

  EXPECT_EQ(result["num_frames"], 12);
  EXPECT_EQ(result["num_tracked"], 12);
  int keyframes = 0;
  for (const json& frame : result["frames"]) {
    EXPECT_NE(frame["state"], "lost") << frame["name"] << ": " << frame["reason"];
    keyframes += frame["keyframe"].get<bool>() ? 1 : 0;
  }
  // The first and the last frame are keyframes. The room is in view all along the 2.2 m, so
  // the last keyframes may recognise the first ones: such loops are right to millimetres.
  EXPECT_TRUE(result["frames"][0]["keyframe"].get<bool>());
  EXPECT_TRUE(result["frames"][11]["keyframe"].get<bool>());
  EXPECT_EQ(result["num_keyframes"].get<int>(), keyframes);
  ASSERT_TRUE(result["loops"].is_array());
  for (const json& loop : result["loops"]) {
    const int i = loop["frame_index"].get<int>(), j = loop["matched_frame_index"].get<int>();
    EXPECT_LT(j, i);
    EXPECT_EQ(loop["frame"], result["frames"][i]["name"]);
    EXPECT_EQ(loop["matched_frame"], result["frames"][j]["name"]);
    EXPECT_TRUE(result["frames"][i]["keyframe"].get<bool>());
    EXPECT_GE(loop["inliers"].get<int>(), 40);
    EXPECT_LT(loop["correction_m"].get<double>(), 0.02) << loop.dump();
    EXPECT_LT(loop["correction_deg"].get<double>(), 0.5) << loop.dump();
  }
  EXPECT_TRUE(result["timings_s"].contains("loop"));
  const json& evaluation = result["evaluation"];
  double gt_length = 0;
  for (size_t i = 1; i < sequence_->world_from_rig.size(); ++i) {
    gt_length += (sequence_->world_from_rig[i].translation -
                  sequence_->world_from_rig[i - 1].translation).norm();
  }
  EXPECT_NEAR(evaluation["path_length_m"].get<double>(), gt_length, 1e-6);
  EXPECT_LT(evaluation["final_drift_percent"].get<double>(), 3.0) << evaluation.dump(2);
  EXPECT_LT(evaluation["ate_rmse_m"].get<double>(), 0.02);
  // The figures evo plots: each frame's error against the distance travelled, and the relative
  // pose error over 1 m and 10 m of path (the sequence is shorter than 10 m: no such segment).
  EXPECT_EQ(evaluation["per_frame"]["distance_m"].size(), 12u);
  EXPECT_EQ(evaluation["per_frame"]["translation_error_m"].size(), 12u);
  EXPECT_NEAR(evaluation["per_frame"]["distance_m"].back().get<double>(), gt_length, 1e-6);
  ASSERT_EQ(evaluation["rpe_segments"].size(), 2u);
  EXPECT_EQ(evaluation["rpe_segments"][0]["length_m"], 1.0);
  EXPECT_GT(evaluation["rpe_segments"][0]["num_segments"].get<int>(), 0);
  EXPECT_LT(evaluation["rpe_segments"][0]["translation_mean_percent"].get<double>(), 3.0);
  EXPECT_GT(result["num_map_points"].get<int>(), 500);
  ASSERT_FALSE(result["global_bundle_adjustment"].is_null());
  EXPECT_LT(result["global_bundle_adjustment"]["final_rms_px"].get<double>(), 1.0);

  // Artifacts: trajectory.json (one entry per frame), TUM (one line per tracked frame), PLY.
  std::ifstream trajectory_file(context_.output_dir / "trajectory.json");
  const json trajectory = json::parse(trajectory_file);
  EXPECT_EQ(trajectory["frames"].size(), 12u);
  EXPECT_EQ(trajectory["frames"][3]["world_from_rig"]["rotation_wxyz"].size(), 4u);
  EXPECT_EQ(slam::ReadTum(context_.output_dir / "trajectory.tum").size(), 12u);
  std::ifstream kitti(context_.output_dir / "trajectory.kitti.txt");
  int kitti_lines = 0;
  for (std::string row; std::getline(kitti, row);) ++kitti_lines;
  EXPECT_EQ(kitti_lines, 12);
  std::ifstream ply(context_.output_dir / "map.ply", std::ios::binary);
  std::string line;
  std::getline(ply, line);
  EXPECT_EQ(line, "ply");
  std::getline(ply, line);
  EXPECT_EQ(line, "format binary_little_endian 1.0");
  EXPECT_TRUE(fs::exists(context_.output_dir / "report.json"));

  ASSERT_FALSE(fractions.empty());
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
}

TEST_F(SlamJob, DenseMapFusesKeyframesAndWritesAnOccupancyGrid) {
  const JobType job_type = SlamJobType();
  EXPECT_EQ(job_type.name, "slam");
  const JobType* type = &job_type;
  // Keyframes 0.5 m apart on this short sequence, on the full-resolution grid (the defaults,
  // 1.5 m and 1.25, are chosen for 1024x768; at 640x480 a coarser grid leaves few points under
  // the map's 2 % range std: 6,609 instead of 40,569).
  const json params = {
      {"rig", "rig-job"},
      {"dense_map", {{"voxel_m", 0.02}, {"keyframe_spacing_m", 0.5}, {"grid_step_factor", 1}}}};
  type->validate(params);
  EXPECT_THROW(type->validate({{"rig", "rig-job"}, {"dense_map", {{"voxel", 0.02}}}}),
               InvalidArgument);
  EXPECT_THROW(type->validate({{"rig", "rig-job"}, {"dense_map", {{"voxel_m", 0.0}}}}),
               InvalidArgument);
  // The map's rectification tables are kept in the service's cache folder, as the
  // stereo_reconstruct job keeps them: one file for the rig and the map's grid.
  context_.cache_dir = context_.output_dir.parent_path() / "cache_dense_map";
  fs::remove_all(context_.cache_dir);
  const json result = type->run(params, context_);
  std::vector<std::string> tables;
  for (const auto& entry : fs::directory_iterator(context_.cache_dir / "rectification")) {
    tables.push_back(entry.path().filename().string());
  }
  ASSERT_EQ(tables.size(), 1u);
  EXPECT_EQ(tables[0].rfind("rectification-v1-", 0), 0u) << tables[0];
  fs::remove_all(context_.cache_dir);
  ASSERT_TRUE(result.contains("dense_map")) << result.dump(2);
  const json& map = result["dense_map"];
  // ~20 cm steps over 1.65 m with keyframes 0.5 m apart.
  EXPECT_GE(map["keyframes"].size(), 3u);
  EXPECT_EQ(map["keyframe_spacing_m"], 0.5);
  EXPECT_EQ(map["grid_step_factor"], 1.0);
  EXPECT_GT(map["num_points"].get<int>(), 20000);  // 40,569 measured (640x480)
  // The sensor is 1 m above the floor; the world is the first frame's cam0 frame (z down).
  EXPECT_NEAR(map["floor_height_m"].get<double>(), -1.0, 0.05);
  EXPECT_EQ(result["artifacts"]["dense_map_ply"], "dense_map.ply");
  for (const char* file : {"dense_map.ply", "occupancy.pgm", "occupancy.yaml"}) {
    EXPECT_TRUE(fs::exists(context_.output_dir / file)) << file;
  }
  const cv::Mat occupancy =
      cv::imread((context_.output_dir / "occupancy.pgm").string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(occupancy.empty());
  EXPECT_GT(cv::countNonZero(occupancy == 0), 30);     // occupied cells (82 measured)
  EXPECT_GT(cv::countNonZero(occupancy == 254), 1000);  // free cells
}

TEST_F(SlamJob, RefinesAWrongFocalLengthAndReportsTheCalibrationBeforeAndAfter) {
  // The rig job's cameras claim focal lengths 0.5 % too long (1 px at this size).
  StereoRig given = sequence_->rig;
  for (CameraModel* camera : {&given.cam0, &given.cam1}) {
    camera->intrinsics.gamma_u() *= 1.005;
    camera->intrinsics.gamma_v() *= 1.005;
  }
  const json rig = RigToJson(given);
  context_.load_result = [rig](const std::string&) { return rig; };
  const JobType job_type = SlamJobType();
  EXPECT_EQ(job_type.name, "slam");
  const JobType* type = &job_type;
  const json params = {{"rig", "rig-job"}, {"options", {{"refine_calibration", "intrinsics"}}}};
  type->validate(params);
  const json result = type->run(params, context_);

  const json& refinement = result["calibration_refinement"];
  ASSERT_TRUE(refinement.is_object()) << result.dump();
  EXPECT_TRUE(refinement["applied"].get<bool>()) << refinement["reason"];
  EXPECT_EQ(refinement["refine"], "intrinsics");
  EXPECT_EQ(refinement["before"]["cameras"], rig["cameras"]);
  EXPECT_EQ(refinement["after"]["cam0_from_cam1"], rig["cam0_from_cam1"]);  // not refined
  EXPECT_EQ(refinement["free_parameters"].size(), 8u);
  const CameraModel* truth[2] = {&sequence_->rig.cam0, &sequence_->rig.cam1};
  for (int c = 0; c < 2; ++c) {
    const std::string cam = "cam" + std::to_string(c);
    const double before = refinement["before"]["cameras"][cam]["intrinsics"]["gamma_u"];
    const double after = refinement["after"]["cameras"][cam]["intrinsics"]["gamma_u"];
    const double true_gamma = truth[c]->intrinsics.gamma_u();
    EXPECT_LT(std::abs(after - true_gamma), 0.5 * std::abs(before - true_gamma)) << cam;
    EXPECT_NEAR(refinement["change"][cam]["gamma_u"].get<double>(), after - before, 1e-9);
  }
  EXPECT_LT(refinement["reprojection_rms_px"]["final"].get<double>(),
            refinement["reprojection_rms_px"]["initial"].get<double>());
}

TEST_F(SlamJob, ABlackFrameIsLostAndTheSequenceGoesOn) {
  const fs::path black = context_.dataset_dir / ("cam0/" + sequence_->names[5] + ".png");
  cv::imwrite(black.string(), cv::Mat(sequence_->images[0][5].size(), CV_8UC3, cv::Scalar::all(0)));
  json result;
  try {
    result = RunSlamJob({{"rig", "rig-job"}, {"ground_truth", "gt.tum"}}, context_);
  } catch (...) {
    cv::imwrite(black.string(), sequence_->images[0][5]);
    throw;
  }
  cv::imwrite(black.string(), sequence_->images[0][5]);  // the other tests use the real frame
  const json& frames = result["frames"];
  EXPECT_EQ(frames[5]["state"], "lost");
  EXPECT_NE(frames[5]["reason"].get<std::string>().find("black"), std::string::npos);
  EXPECT_TRUE(frames[5]["world_from_rig"].is_null());
  for (int i = 6; i < 12; ++i) EXPECT_NE(frames[i]["state"], "lost") << i;
  EXPECT_EQ(result["num_tracked"], 11);
  EXPECT_LT(result["evaluation"]["final_drift_percent"].get<double>(), 5.0);
}

TEST_F(SlamJob, AFrameThatCannotBeTrackedReinitialisesAndTheNextOneRelocalises) {
  // Frame 5 shows another scene (a street seen by the same rig): it passes the front end but
  // cannot be tracked, so it starts an unlinked segment. Frame 6 fails against it and is
  // relocalised against frame 4, back in the first frame's world.
  synth::StereoSequenceOptions street_options;
  street_options.environment = synth::StereoSequenceOptions::Environment::kStreet;
  street_options.num_frames = 1;
  street_options.width = 640;
  street_options.height = 480;
  street_options.render.noise_sigma = 1.0;
  const synth::StereoSequence street = synth::MakeStereoSequence(street_options);
  fs::path replaced[2];
  for (int c = 0; c < 2; ++c) {
    replaced[c] = context_.dataset_dir / ("cam" + std::to_string(c) + "/" + sequence_->names[5] + ".png");
    cv::imwrite(replaced[c].string(), street.images[c][0]);
  }
  auto restore = [&] {
    for (int c = 0; c < 2; ++c) cv::imwrite(replaced[c].string(), sequence_->images[c][5]);
  };
  json result;
  try {
    result = RunSlamJob({{"rig", "rig-job"}, {"ground_truth", "gt.tum"}}, context_);
  } catch (...) {
    restore();
    throw;
  }
  restore();
  const json& frames = result["frames"];
  EXPECT_EQ(frames[5]["state"], "reinitialised") << frames[5]["reason"];
  EXPECT_FALSE(frames[5]["linked"].get<bool>());
  EXPECT_EQ(frames[6]["state"], "relocalised") << frames[6]["reason"];
  for (int i = 0; i < 12; ++i) {
    if (i == 5) continue;
    EXPECT_TRUE(frames[i]["linked"].get<bool>()) << i;
    EXPECT_NE(frames[i]["state"], "reinitialised") << i;
  }
  // Frames after the break are in the first frame's world: their positions agree with the
  // ground truth (the first pose anchors both).
  const Rigid3d world_from_first = sequence_->world_from_rig[0];
  for (int i : {6, 11}) {
    const Eigen::Vector3d t(frames[i]["world_from_rig"]["translation_m"][0].get<double>(),
                            frames[i]["world_from_rig"]["translation_m"][1].get<double>(),
                            frames[i]["world_from_rig"]["translation_m"][2].get<double>());
    const Eigen::Vector3d truth = world_from_first.Inverse() * sequence_->world_from_rig[i].translation;
    EXPECT_LT((t - truth).norm(), 0.05) << i;
  }
}

TEST_F(SlamJob, CancellationStopsTheRun) {
  int reports = 0;
  context_.progress.report = [&](double, const std::string&, const std::string&) { ++reports; };
  context_.progress.is_cancelled = [&] { return reports >= 3; };
  EXPECT_THROW(RunSlamJob({{"rig", "rig-job"}}, context_), Cancelled);
  EXPECT_LT(reports, 6);
}

TEST_F(SlamJob, RefusesAnUnknownRigJob) {
  EXPECT_THROW(RunSlamJob({{"rig", "nope"}}, context_), InvalidArgument);
}

}  // namespace
}  // namespace omnirig::api
