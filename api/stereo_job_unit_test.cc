#include "api/stereo_job.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "engine/dense/dense_map.h"
#include "engine/geometry/unified_camera.h"
#include "engine/slam/map_io.h"
#include "engine/synth/presets.h"
#include "engine/util/check.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

StereoRig Rig() {
  StereoRig rig;
  for (CameraModel* camera : {&rig.cam0, &rig.cam1}) {
    camera->intrinsics.params = {0.94, 75.0, 75.5, 160.0, 120.0, 0.0, -0.06, 0.012, 0, 0, 0};
    camera->width = 320;
    camera->height = 240;
  }
  rig.cam0_from_cam1 = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 0.1));
  return rig;
}

TEST(StereoJson, ParsesParamsAndRefusesBadOnes) {
  const StereoReconstructParams parsed = StereoReconstructParamsFromJson(
      {{"rig", "job-1"}, {"method", "sparse"}, {"ratio_test", 0.7}, {"max_features", 1000},
       {"mutual_check", false}});
  EXPECT_EQ(parsed.rig_job, "job-1");
  EXPECT_EQ(parsed.method, "sparse");
  EXPECT_EQ(parsed.options.ratio_test, 0.7);
  EXPECT_EQ(parsed.options.max_features, 1000);
  EXPECT_FALSE(parsed.options.mutual_check);
  EXPECT_THROW(StereoReconstructParamsFromJson(json::object()), InvalidArgument);
  EXPECT_THROW(StereoReconstructParamsFromJson({{"rig", 5}}), InvalidArgument);
  EXPECT_THROW(StereoReconstructParamsFromJson({{"rig", "a"}, {"ratio", 0.7}}), InvalidArgument);
  const auto sparse = [](const std::string& key, const json& value) {
    return json{{"rig", "a"}, {"method", "sparse"}, {key, value}};
  };
  EXPECT_THROW(StereoReconstructParamsFromJson(sparse("ratio_test", "x")),
               InvalidArgument);
  EXPECT_THROW(StereoReconstructParamsFromJson(sparse("ratio_test", 2.0)),
               InvalidArgument);
  EXPECT_THROW(StereoReconstructParamsFromJson(sparse("max_features", 1.5)),
               InvalidArgument);
  try {
    StereoReconstructParamsFromJson({{"rig", "a"}, {"bogus", 1}});
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("params.bogus"), std::string::npos);
  }
}

TEST(StereoJson, DenseIsTheDefaultMethod) {
  const StereoReconstructParams parsed = StereoReconstructParamsFromJson(
      {{"rig", "job-1"}, {"min_confidence", 0.6}, {"grid_step_rad", 0.004}, {"block_size", 7},
       {"dark_level", 30.0}});
  EXPECT_EQ(parsed.method, "dense");
  EXPECT_EQ(parsed.dense.min_confidence, 0.6);
  EXPECT_EQ(parsed.dense.grid.step_rad, 0.004);
  EXPECT_EQ(parsed.dense.block_size, 7);
  EXPECT_EQ(parsed.dense.dark_level, 30.0);
  EXPECT_EQ(DenseStereoOptionsToJson(parsed.dense)["grid_step_rad"], 0.004);
  // A field of the other method is named as such.
  try {
    StereoReconstructParamsFromJson({{"rig", "a"}, {"ratio_test", 0.7}});
    ADD_FAILURE() << "expected InvalidArgument";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("applies to method 'sparse' only"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(StereoReconstructParamsFromJson({{"rig", "a"}, {"method", "sparse"}, {"block_size", 5}}),
               InvalidArgument);
  EXPECT_THROW(StereoReconstructParamsFromJson({{"rig", "a"}, {"method", "fast"}}), InvalidArgument);
  EXPECT_THROW(StereoReconstructParamsFromJson({{"rig", "a"}, {"block_size", 4}}), InvalidArgument);
  EXPECT_THROW(StereoReconstructParamsFromJson({{"rig", "a"}, {"min_confidence", "high"}}),
               InvalidArgument);
}

TEST(StereoJson, RegistersTheJobType) {
  const JobType job_type = StereoReconstructJobType();
  EXPECT_EQ(job_type.name, "stereo_reconstruct");
  const JobType* type = &job_type;
  EXPECT_EQ(type->referenced_jobs({{"rig", "abc"}}),
            (std::vector<JobReference>{{"abc", "relative_pose", "rig"}}));
  EXPECT_EQ(type->referenced_jobs({{"rig", "abc"}, {"trajectory", "s1"}}),
            (std::vector<JobReference>{{"abc", "relative_pose", "rig"},
                                       {"s1", "slam", "trajectory"}}));
  EXPECT_THROW(type->validate(json::object()), InvalidArgument);
}

TEST(StereoJson, EpipolarCurveJson) {
  json result = RigToJson(Rig());
  result["rms_px"] = 0.1;  // a relative_pose result holds more keys than the rig
  const json curve = EpipolarCurveJson(result, 0, 220.0, 120.0);
  EXPECT_EQ(curve["from"], "cam0");
  EXPECT_EQ(curve["to"], "cam1");
  EXPECT_EQ(curve["pixel"], json::array({220.0, 120.0}));
  ASSERT_TRUE(curve["polylines"].is_array());
  ASSERT_FALSE(curve["polylines"].empty());
  for (const json& line : curve["polylines"]) {
    ASSERT_GE(line.size(), 2u);
    for (const json& p : line) {
      ASSERT_EQ(p.size(), 2u);
      EXPECT_TRUE(p[0].is_number() && p[1].is_number());
    }
  }
  EXPECT_EQ(EpipolarCurveJson(result, 1, 220.0, 120.0)["to"], "cam0");
  EXPECT_THROW(EpipolarCurveJson(result, 2, 220.0, 120.0), InvalidArgument);
  EXPECT_THROW(EpipolarCurveJson(result, 0, NAN, 384.0), InvalidArgument);
  EXPECT_THROW(EpipolarCurveJson(json::object(), 0, 220.0, 120.0), InvalidArgument);
}

class StereoJobTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = std::filesystem::temp_directory_path() /
            ("omnirig_stereo_job_" + std::to_string(::getpid()));
    std::filesystem::remove_all(root_);
    std::filesystem::create_directories(root_ / "data" / "cam0");
    std::filesystem::create_directories(root_ / "data" / "cam1");
    std::filesystem::create_directories(root_ / "out");
    context_.dataset_dir = root_ / "data";
    context_.output_dir = root_ / "out";
    context_.progress.report = [this](double fraction, const std::string&, const std::string&) {
      EXPECT_GE(fraction, last_fraction_);
      last_fraction_ = fraction;
    };
    context_.load_result = [](const std::string& id) -> json {
      if (id == "rig") return RigToJson(Rig());
      if (id == "calib") return {{"camera", CameraToJson(Rig().cam0)}};
      throw InvalidArgument("no result for job " + id);
    };
  }
  void TearDown() override { std::filesystem::remove_all(root_); }

  void AddImage(const std::string& name, int width, int height) {
    cv::imwrite((context_.dataset_dir / name).string(),
                cv::Mat(height, width, CV_8UC3, cv::Scalar(6, 6, 6)));
    context_.image_names.push_back(name);
    std::sort(context_.image_names.begin(), context_.image_names.end());
  }

  std::filesystem::path root_;
  JobContext context_;
  double last_fraction_ = 0.0;
};

TEST_F(StereoJobTest, RunsAndWritesThePly) {
  AddImage("cam0/a.png", 320, 240);
  AddImage("cam1/a.png", 320, 240);
  const json result = RunStereoReconstructJob({{"rig", "rig"}, {"method", "sparse"}}, context_);
  EXPECT_EQ(result["method"], "sparse");
  EXPECT_EQ(result["artifact"], "cloud.ply");
  EXPECT_EQ(result["num_points"], 0);  // dark images: nothing to match, but a valid result
  ASSERT_EQ(result["pairs"].size(), 1u);
  EXPECT_EQ(result["pairs"][0]["name"], "a.png");
  EXPECT_TRUE(std::filesystem::exists(context_.output_dir / "cloud.ply"));
  EXPECT_EQ(last_fraction_, 1.0);
}

// Pairs of a moving rig do not share a frame: each keeps its own cloud, none is merged.
TEST_F(StereoJobTest, SparseSeveralPairsKeepTheirCloudsApart) {
  for (const char* name : {"cam0/a.png", "cam1/a.png", "cam0/b.png", "cam1/b.png"}) {
    AddImage(name, 320, 240);
  }
  const json result = RunStereoReconstructJob({{"rig", "rig"}, {"method", "sparse"}}, context_);
  ASSERT_EQ(result["pairs"].size(), 2u);
  EXPECT_FALSE(std::filesystem::exists(context_.output_dir / "cloud.ply"));
  EXPECT_EQ(result["clouds_merged"], false);
  EXPECT_EQ(result["artifact"], result["pairs"][0]["artifact"]);
  for (const json& pair : result["pairs"]) {
    EXPECT_TRUE(std::filesystem::exists(context_.output_dir / pair["artifact"].get<std::string>()));
  }
}

TEST_F(StereoJobTest, DenseWritesCloudsAndRangePanoramasAndFlagsBadPairs) {
  for (const std::string name : {"a.png", "b.png"}) {
    AddImage("cam0/" + name, 320, 240);
    AddImage("cam1/" + name, 320, 240);
  }
  const json result = RunStereoReconstructJob({{"rig", "rig"}}, context_);
  EXPECT_EQ(result["method"], "dense");
  EXPECT_EQ(result["artifact"], "cloud_a_png.ply");  // two pairs: no merged cloud
  EXPECT_EQ(result["clouds_merged"], false);
  EXPECT_EQ(result["num_points"], 0);  // dark images: nothing inside a mirror
  ASSERT_EQ(result["pairs"].size(), 2u);
  const json& pair = result["pairs"][0];
  EXPECT_EQ(pair["name"], "a.png");
  EXPECT_EQ(pair["artifact"], "cloud_a_png.ply");
  EXPECT_EQ(pair["range_tiff"], "a_range.tiff");
  EXPECT_EQ(pair["range_png"], "a_range.png");
  EXPECT_NE(pair["warning"].get<std::string>().find("few confident pixels"), std::string::npos);
  EXPECT_NE(result["warning"].get<std::string>().find("2 of 2 pairs"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(context_.output_dir / "cloud.ply"));
  for (const char* file : {"cloud_a_png.ply", "cloud_b_png.ply", "a_range.tiff", "a_range.png",
                           "b_range.tiff"}) {
    EXPECT_TRUE(std::filesystem::exists(context_.output_dir / file)) << file;
  }
  const cv::Mat range =
      cv::imread((context_.output_dir / "a_range.tiff").string(), cv::IMREAD_UNCHANGED);
  EXPECT_EQ(range.type(), CV_32FC1);
  EXPECT_EQ(cv::countNonZero(range), 0);
  std::ifstream ply(context_.output_dir / "cloud_a_png.ply");
  const std::string header((std::istreambuf_iterator<char>(ply)), std::istreambuf_iterator<char>());
  EXPECT_NE(header.find("property float confidence"), std::string::npos);
  EXPECT_NE(header.find("property float range_std_m"), std::string::npos);
  EXPECT_EQ(last_fraction_, 1.0);
}

// The rig's rectification tables are kept in the cache folder the service gives (one file per
// rig and grid), not among the job's artifacts.
TEST_F(StereoJobTest, DenseKeepsTheRigsRectificationTablesInTheCacheFolder) {
  AddImage("cam0/a.png", 320, 240);
  AddImage("cam1/a.png", 320, 240);
  context_.cache_dir = root_ / "cache";
  RunStereoReconstructJob({{"rig", "rig"}}, context_);
  std::vector<std::string> tables;
  for (const auto& entry : std::filesystem::directory_iterator(root_ / "cache" / "rectification")) {
    tables.push_back(entry.path().filename().string());
  }
  ASSERT_EQ(tables.size(), 1u);
  EXPECT_EQ(tables[0].rfind("rectification-v1-", 0), 0u) << tables[0];
  for (const auto& entry : std::filesystem::directory_iterator(context_.output_dir)) {
    EXPECT_EQ(entry.path().filename().string().find("rectification"), std::string::npos);
  }
}

// Pair k's files are written while pair k + 1 is matched: a failed write stops the job with an
// error naming the pair, and the next pair's files are not written.
TEST_F(StereoJobTest, DenseWriteErrorNamesThePairAndStopsTheJob) {
  for (const std::string name : {"a.png", "b.png", "c.png"}) {
    AddImage("cam0/" + name, 320, 240);
    AddImage("cam1/" + name, 320, 240);
  }
  std::filesystem::create_directories(context_.output_dir / "a_range.png");  // not writable
  try {
    RunStereoReconstructJob({{"rig", "rig"}}, context_);
    ADD_FAILURE() << "expected the write error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("pair 'a.png': cannot write"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("a_range.png"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(std::filesystem::exists(context_.output_dir / "a_range.tiff"));
  EXPECT_FALSE(std::filesystem::exists(context_.output_dir / "cloud_a_png.ply"));
  for (const char* file : {"b_range.tiff", "b_range.png", "cloud_b_png.ply", "c_range.tiff"}) {
    EXPECT_FALSE(std::filesystem::exists(context_.output_dir / file)) << file;
  }
}

// The InvalidArgument message of running the job, or "" when it does not throw one.
std::string RunError(const json& params, const JobContext& context) {
  try {
    RunStereoReconstructJob(params, context);
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "";
}

TEST_F(StereoJobTest, RefusesBadInput) {
  AddImage("cam0/a.png", 320, 240);
  AddImage("cam1/a.png", 640, 480);
  EXPECT_NE(RunError({{"rig", "rig"}}, context_).find("cam1 image is 640x480"), std::string::npos);
  EXPECT_NE(RunError({{"rig", "rig"}, {"method", "sparse"}}, context_).find("cam1 image is 640x480"),
            std::string::npos);
  // A job whose result holds no rig, and a job without a result.
  EXPECT_NE(RunError({{"rig", "calib"}}, context_).find("holds no stereo rig"), std::string::npos);
  EXPECT_NE(RunError({{"rig", "missing"}}, context_).find("no result"), std::string::npos);
  AddImage("cam0/b.png", 320, 240);  // no partner
  EXPECT_NE(RunError({{"rig", "rig"}}, context_).find("without a partner"), std::string::npos);
}

// The vertices of a binary PLY with float x y z, uchar rgb and (dense) float confidence and
// range_std_m.
std::vector<Eigen::Vector3f> PlyVertices(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  const std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t element = data.find("element vertex ");
  const size_t count = std::stoul(data.substr(element + 15));
  const size_t body = data.find("end_header\n") + 11;
  const size_t stride = 15 + 4 * (data.find("property float confidence") < body) +
                        4 * (data.find("property float range_std_m") < body);
  EXPECT_EQ(data.size(), body + stride * count) << path;
  std::vector<Eigen::Vector3f> vertices(count);
  for (size_t i = 0; i < count && body + stride * (i + 1) <= data.size(); ++i) {
    std::memcpy(vertices[i].data(), data.data() + body + stride * i, 3 * sizeof(float));
  }
  return vertices;
}

// Two rendered pairs of a moving rig (320x240), their rig and poses.
class StereoTrajectoryTest : public StereoJobTest {
 protected:
  void SetUp() override {
    StereoJobTest::SetUp();
    synth::StereoSequenceOptions options;
    options.num_frames = 2;
    options.width = 320;
    options.height = 240;
    options.path_length_m = 1.0;
    sequence_ = synth::MakeStereoSequence(options);
    for (int f = 0; f < 2; ++f) {
      for (int c = 0; c < 2; ++c) {
        const std::string name = "cam" + std::to_string(c) + "/" + sequence_.names[f] + ".png";
        cv::imwrite((context_.dataset_dir / name).string(), sequence_.images[c][f]);
        context_.image_names.push_back(name);
      }
    }
    std::sort(context_.image_names.begin(), context_.image_names.end());
    context_.load_result = [this](const std::string& id) -> json {
      if (id == "rig") return RigToJson(sequence_.rig);
      json frames = json::array();
      for (int f = 0; f < 2; ++f) {
        frames.push_back({{"name", sequence_.names[f] + ".png"},
                          {"world_from_rig", PoseToJson(sequence_.world_from_rig[f])}});
      }
      frames.push_back({{"name", "lost.png"}, {"world_from_rig", nullptr}});
      return {{"frames", frames}};
    };
  }

  // Checks cloud.ply: both pairs, the second's first point moved by its pose (sparse: the
  // pairs' points appended).
  void ExpectMerged(const json& result, const std::string& source) {
    ExpectPlaced(result, source);
    const size_t first = result["pairs"][0]["num_points"].get<size_t>();
    const size_t second = result["pairs"][1]["num_points"].get<size_t>();
    const std::vector<Eigen::Vector3f> merged = PlyVertices(context_.output_dir / "cloud.ply");
    const std::vector<Eigen::Vector3f> in_cam0 =
        PlyVertices(context_.output_dir / result["pairs"][1]["artifact"].get<std::string>());
    ASSERT_EQ(merged.size(), first + second);
    ASSERT_EQ(in_cam0.size(), second);
    const Eigen::Vector3d expected = sequence_.world_from_rig[1] * in_cam0[0].cast<double>();
    EXPECT_LT((merged[first].cast<double>() - expected).norm(), 1e-4);
  }

  // Checks cloud.ply of dense pairs: fused into 1 cm voxels (engine/dense MergedCloudOptions),
  // so fewer points than the pairs hold, each the mean of pair points in its voxel (within a
  // voxel's diagonal of a point of either pair placed by its pose), then moved along the other
  // pair's ray to the weighted mean of the two ranges where they agree: by at most the agreement
  // tolerance, 3 combined range stds, each at most 2 % of the range.
  void ExpectFused(const json& result, const std::string& source) {
    ExpectPlaced(result, source);
    std::vector<Eigen::Vector3d> placed;
    for (int k = 0; k < 2; ++k) {
      const std::vector<Eigen::Vector3f> pair =
          PlyVertices(context_.output_dir / result["pairs"][k]["artifact"].get<std::string>());
      EXPECT_EQ(pair.size(), result["pairs"][k]["num_points"].get<size_t>());
      for (const Eigen::Vector3f& p : pair) {
        placed.push_back(sequence_.world_from_rig[k] * p.cast<double>());
      }
    }
    const std::vector<Eigen::Vector3f> merged = PlyVertices(context_.output_dir / "cloud.ply");
    ASSERT_GT(merged.size(), 20u);
    EXPECT_LT(merged.size(), placed.size());
    std::vector<double> nearest_m;
    for (size_t i = 0; i < merged.size(); i += std::max<size_t>(1, merged.size() / 50)) {
      double nearest = 1e9, range_m = 1e9;
      for (const Eigen::Vector3d& p : placed) {
        nearest = std::min(nearest, (p - merged[i].cast<double>()).norm());
      }
      for (int k = 0; k < 2; ++k) {
        range_m = std::min(
            range_m, (merged[i].cast<double>() - sequence_.world_from_rig[k].translation).norm());
      }
      const double max_move_m = 3.0 * std::sqrt(2.0) * 0.02 * (range_m + 0.0174);
      EXPECT_LT(nearest, 0.0174 + max_move_m) << "fused point " << i;
      nearest_m.push_back(nearest);
    }
    // Most points move by less than their voxel's size.
    std::sort(nearest_m.begin(), nearest_m.end());
    EXPECT_LT(nearest_m[nearest_m.size() / 2], 0.0174);
    EXPECT_GT(result["merged_points_per_m2"].get<double>(), 0.0);
    EXPECT_DOUBLE_EQ(result["merged_points_per_m2"].get<double>(),
                     dense::PointsPerSquareMetre(merged));
  }

  void ExpectPlaced(const json& result, const std::string& source) {
    EXPECT_EQ(result["artifact"], "cloud.ply");
    EXPECT_EQ(result["clouds_merged"], true);
    EXPECT_EQ(result["trajectory"]["source"], source);
    EXPECT_EQ(result["trajectory"]["num_pairs_placed"], 2);
    EXPECT_FALSE(result["trajectory"].contains("warning"));
    ASSERT_GT(result["pairs"][0]["num_points"].get<size_t>(), 20u);
    ASSERT_GT(result["pairs"][1]["num_points"].get<size_t>(), 20u);
  }

  synth::StereoSequence sequence_;
};

TEST_F(StereoTrajectoryTest, ASlamJobPlacesThePairsInItsWorld) {
  const json result = RunStereoReconstructJob({{"rig", "rig"}, {"trajectory", "slam"}}, context_);
  ExpectFused(result, "slam job slam");
  EXPECT_EQ(result["pairs"][0]["placed"], true);
  // A slam job none of whose frames is a pair of the dataset is refused.
  context_.load_result = [this](const std::string& id) -> json {
    if (id == "rig") return RigToJson(sequence_.rig);
    return {{"frames", json::array({{{"name", "other.png"}, {"world_from_rig", nullptr}}})}};
  };
  EXPECT_NE(RunError({{"rig", "rig"}, {"trajectory", "slam"}}, context_).find("no pair"),
            std::string::npos);
}

TEST_F(StereoTrajectoryTest, TheDatasetsTumTrajectoryPlacesThePairsInOrder) {
  std::vector<slam::StampedPose> poses;
  for (int f = 0; f < 2; ++f) poses.push_back({0.1 * f, sequence_.world_from_rig[f]});
  slam::WriteTum(context_.dataset_dir / "truth.tum", poses);
  context_.image_names.push_back("truth.tum");
  std::sort(context_.image_names.begin(), context_.image_names.end());
  ExpectMerged(RunStereoReconstructJob({{"rig", "rig"}, {"method", "sparse"}}, context_),
               "truth.tum");
  // One pose too many: not placed, and said so; the pairs keep their own clouds.
  last_fraction_ = 0.0;
  poses.push_back(poses.back());
  slam::WriteTum(context_.dataset_dir / "truth.tum", poses);
  const json result = RunStereoReconstructJob({{"rig", "rig"}, {"method", "sparse"}}, context_);
  EXPECT_EQ(result["clouds_merged"], false);
  EXPECT_NE(result["trajectory"]["warning"].get<std::string>().find("3 poses for 2 pairs"),
            std::string::npos);
}

}  // namespace
}  // namespace omnirig::api
