#include "api/synth_json.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include <gtest/gtest.h>
#include <unistd.h>

#include "api/camera_json.h"
#include "engine/slam/map_io.h"

namespace omnirig::api {
namespace {

synth::MonoCalibrationSet SmallMonoSet() {
  synth::MonoCalibrationOptions options;
  options.num_views = 2;
  options.width = 320;
  options.height = 240;
  options.poses.min_square_px = 3.0;
  options.render.supersampling = 1;
  return synth::MakeMonoCalibrationSet(options);
}

// A hand-made sequence (no rendering) with a NaN-free trajectory of two frames.
synth::StereoSequence SmallSequence() {
  synth::StereoSequence sequence;
  sequence.cameras = {synth::DefaultCamera(128, 96), synth::DefaultSecondCamera(128, 96)};
  sequence.rig.cam0 = sequence.cameras[0].model;
  sequence.rig.cam1 = sequence.cameras[1].model;
  sequence.rig.cam0_from_cam1 = synth::DefaultCam0FromCam1();
  synth::TextureSpec plain;
  plain.style = synth::TextureSpec::Style::kPlain;
  sequence.scene.AddPlane(Rigid3d(), 2.0, 2.0, plain, "floor");
  for (int i = 0; i < 2; ++i) {
    sequence.names.push_back("frame_00" + std::to_string(i));
    sequence.timestamps_s.push_back(0.1 * i);
    sequence.world_from_rig.push_back(
        synth::WorldFromUprightCamera(Eigen::Vector3d(i, 0, 1), 0.2 * i));
    for (int k = 0; k < 2; ++k)
      sequence.images[k].push_back(cv::Mat(96, 128, CV_8UC3, cv::Scalar::all(9)));
  }
  return sequence;
}

TEST(SynthJson, MonoSetHasTheDocumentedKeys) {
  const synth::MonoCalibrationSet set = SmallMonoSet();
  const nlohmann::json json = MonoCalibrationSetToJson(set);
  EXPECT_EQ(json["preset"], "mono-calib");
  EXPECT_EQ(json["image_size"], nlohmann::json({320, 240}));
  for (const char* name :
       {"xi", "gamma_u", "gamma_v", "u0", "v0", "alpha", "k1", "k2", "k3", "k4", "k5"}) {
    EXPECT_TRUE(json["camera"]["intrinsics"].contains(name)) << name;
  }
  EXPECT_DOUBLE_EQ(json["camera"]["rim_radius_px"].get<double>(), set.camera.rim_radius_px);
  EXPECT_TRUE(json["camera"].contains("hole_radius_px"));
  EXPECT_EQ(CameraFromJson(json["camera"]).intrinsics.params, set.camera.model.intrinsics.params);
  EXPECT_EQ(json["board"]["corners_in_board_m"].size(),
            static_cast<size_t>(set.board.cols * set.board.rows));
  ASSERT_EQ(json["images"].size(), 2u);
  const nlohmann::json& image = json["images"][1];
  EXPECT_EQ(image["file"], "view_001.png");
  const Rigid3d pose = PoseFromJson(image["cam_from_board"]);
  EXPECT_LT((pose.translation - set.cam_from_board[1].translation).norm(), 1e-12);
  EXPECT_DOUBLE_EQ(image["corners_px"][5][0].get<double>(), set.corners_px[1][5].x());
  EXPECT_EQ(json["scene"]["world_frame"], "camera");
  EXPECT_EQ(json["scene"]["primitives"][0]["kind"], "box");
  EXPECT_EQ(json["scene"]["primitives"][0]["texture"]["style"], "soft");
}

TEST(SynthJson, CornersThatDoNotProjectAreNull) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const nlohmann::json json = CornersToJson({Eigen::Vector2d(1.5, 2.5), Eigen::Vector2d(nan, nan)});
  EXPECT_EQ(json[0], nlohmann::json({1.5, 2.5}));
  EXPECT_TRUE(json[1].is_null());
}

TEST(SynthJson, SequenceRigAndTrajectory) {
  const synth::StereoSequence sequence = SmallSequence();
  const nlohmann::json json = StereoSequenceToJson(sequence, "room");
  const StereoRig rig = RigFromJson(json["rig"]);
  EXPECT_NEAR(rig.cam0_from_cam1.translation.z(), 0.1, 1e-12);
  EXPECT_TRUE(json["rig"]["cameras"]["cam1"].contains("rim_radius_px"));
  EXPECT_EQ(json["frames"][1]["files"]["cam1"], "cam1/frame_001.png");
  EXPECT_DOUBLE_EQ(json["frames"][1]["timestamp_s"].get<double>(), 0.1);
  EXPECT_TRUE(json["frames"][1]["world_from_rig"].contains("rotation_wxyz"));
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("omnirig_synth_tum_" + std::to_string(::getpid()));
  WriteStereoSequenceGroundTruth(sequence, "room", dir.string());
  const std::vector<slam::StampedPose> tum = slam::ReadTum(dir / "trajectory.tum");
  std::filesystem::remove_all(dir);
  ASSERT_EQ(tum.size(), sequence.world_from_rig.size());
  EXPECT_DOUBLE_EQ(tum[1].timestamp_s, 0.1);
  EXPECT_DOUBLE_EQ(tum[1].world_from_rig.translation.x(), 1.0);
  const Eigen::Quaterniond q = sequence.world_from_rig[1].rotation;
  EXPECT_NEAR(std::abs(tum[1].world_from_rig.rotation.dot(q)), 1.0, 1e-9);
}

TEST(SynthJson, WritersCreateTheLayout) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("omnirig_synth_json_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  WriteMonoCalibrationSet(SmallMonoSet(), (dir / "mono").string());
  EXPECT_TRUE(std::filesystem::exists(dir / "mono" / "view_000.png"));
  std::ifstream in(dir / "mono" / "ground_truth.json");
  const nlohmann::json json = nlohmann::json::parse(in);
  EXPECT_EQ(json["images"].size(), 2u);
  WriteStereoSequence(SmallSequence(), "street", (dir / "seq").string());
  EXPECT_TRUE(std::filesystem::exists(dir / "seq" / "cam1" / "frame_001.png"));
  EXPECT_TRUE(std::filesystem::exists(dir / "seq" / "trajectory.tum"));
  EXPECT_TRUE(std::filesystem::exists(dir / "seq" / "ground_truth.json"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace omnirig::api
