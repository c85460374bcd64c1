#include "engine/synth/presets.h"

#include <cmath>
#include <set>

#include <gtest/gtest.h>

#include "engine/synth/city_block.h"
#include "engine/util/check.h"

namespace omnirig::synth {
namespace {

// FNV-1a over the bytes of images: a digest of a render.
uint64_t Digest(const std::vector<cv::Mat>& images, uint64_t hash = 1469598103934665603ull) {
  for (const cv::Mat& image : images) {
    for (int row = 0; row < image.rows; ++row) {
      const uint8_t* bytes = image.ptr<uint8_t>(row);
      for (size_t i = 0; i < image.cols * image.elemSize(); ++i) {
        hash = (hash ^ bytes[i]) * 1099511628211ull;
      }
    }
  }
  return hash;
}

TEST(Presets, BoardPosesKeepTheBoardInsideTheAnnulusAllAround) {
  const SynthCamera camera = DefaultCamera(640, 480);
  const CheckerboardSpec board;
  const BoardPoseOptions options;
  constexpr int kViews = 12;
  std::set<int> octants;
  for (int view = 0; view < kViews; ++view) {
    const Rigid3d cam_from_board =
        SampleBoardPose({camera}, {Rigid3d()}, board, options, view, kViews, 3);
    for (const Eigen::Vector3d& corner : BoardOutline(board)) {
      EXPECT_TRUE(ProjectVisible(camera, cam_from_board * corner, options.min_margin_px));
    }
    for (const Eigen::Vector2d& pixel : ProjectBoardCorners(camera, cam_from_board, board)) {
      EXPECT_TRUE(InAnnulus(camera, pixel, options.min_margin_px));
    }
    const Eigen::Vector3d centre = cam_from_board * Eigen::Vector3d(0.14, 0.10, 0.0);
    EXPECT_GE(centre.norm(), options.min_distance_m - 0.01);
    EXPECT_LE(centre.norm(), options.max_distance_m + 0.01);
    // The printed side faces the camera, tilted by at most max_tilt_deg.
    const Eigen::Vector3d normal = cam_from_board.rotation * Eigen::Vector3d::UnitZ();
    const double tilt_deg = std::acos(normal.dot(centre.normalized())) * 180.0 / M_PI;
    EXPECT_LE(tilt_deg, options.max_tilt_deg + 1.0);
    const double azimuth = std::atan2(centre.y(), centre.x()) + M_PI;
    octants.insert(static_cast<int>(azimuth / (M_PI / 4)) % 8);
  }
  EXPECT_EQ(octants.size(), 8u);  // views all around the mirror
  // Deterministic in (seed, index).
  const Rigid3d a = SampleBoardPose({camera}, {Rigid3d()}, board, options, 4, kViews, 3);
  const Rigid3d b = SampleBoardPose({camera}, {Rigid3d()}, board, options, 4, kViews, 3);
  EXPECT_EQ(a.translation, b.translation);
}

TEST(Presets, ImpossibleBoardThrows) {
  CheckerboardSpec huge;
  huge.square_size_m = 0.5;
  EXPECT_THROW(
      SampleBoardPose({DefaultCamera(640, 480)}, {Rigid3d()}, huge, BoardPoseOptions(), 0, 1, 0),
      InvalidArgument);
}

TEST(Presets, MonoCalibrationSetHoldsConsistentGroundTruth) {
  MonoCalibrationOptions options;
  options.num_views = 2;
  options.width = 320;
  options.height = 240;
  options.poses.min_square_px = 3.0;
  options.render.supersampling = 1;
  int reports = 0;
  ProgressSink progress;
  progress.report = [&](double, const std::string&, const std::string&) { ++reports; };
  const MonoCalibrationSet set = MakeMonoCalibrationSet(options, progress);
  EXPECT_EQ(reports, 2);
  ASSERT_EQ(set.images.size(), 2u);
  EXPECT_EQ(set.names[1], "view_001");
  EXPECT_EQ(set.images[0].cols, 320);
  ASSERT_EQ(set.corners_px[1].size(), static_cast<size_t>(set.board.cols * set.board.rows));
  const auto expected = ProjectBoardCorners(set.camera, set.cam_from_board[1], set.board);
  EXPECT_EQ(set.corners_px[1], expected);
  options.num_views = 0;
  EXPECT_THROW(MakeMonoCalibrationSet(options), InvalidArgument);
}

TEST(Presets, SameSeedSameSet) {
  MonoCalibrationOptions options;
  options.num_views = 1;
  options.width = 320;
  options.height = 240;
  options.poses.min_square_px = 3.0;
  options.render.supersampling = 1;
  options.render.noise_sigma = 2.0;
  options.seed = 5;
  const MonoCalibrationSet a = MakeMonoCalibrationSet(options);
  const MonoCalibrationSet b = MakeMonoCalibrationSet(options);
  EXPECT_EQ(cv::norm(a.images[0], b.images[0], cv::NORM_INF), 0.0);
  EXPECT_EQ(a.cam_from_board[0].translation, b.cam_from_board[0].translation);
  options.seed = 6;
  const MonoCalibrationSet c = MakeMonoCalibrationSet(options);
  EXPECT_NE(a.cam_from_board[0].translation, c.cam_from_board[0].translation);
}

TEST(Presets, CancellationStopsTheRun) {
  MonoCalibrationOptions options;
  options.num_views = 3;
  options.width = 320;
  options.height = 240;
  options.poses.min_square_px = 3.0;
  options.render.supersampling = 1;
  ProgressSink progress;
  progress.is_cancelled = [] { return true; };
  EXPECT_THROW(MakeMonoCalibrationSet(options, progress), Cancelled);
}

TEST(Presets, StereoBoardSetSeesTheBoardInBothCameras) {
  StereoBoardOptions options;
  options.num_pairs = 1;
  options.width = 320;
  options.height = 240;
  options.poses.min_square_px = 3.0;
  options.render.supersampling = 1;
  const StereoBoardSet set = MakeStereoBoardSet(options);
  EXPECT_NEAR(set.rig.cam0_from_cam1.translation.norm(), 0.1, 1e-12);
  EXPECT_EQ(set.rig.cam1.intrinsics.params, set.cameras[1].model.intrinsics.params);
  ASSERT_EQ(set.images[1].size(), 1u);
  const Rigid3d cam1_from_board = set.rig.cam0_from_cam1.Inverse() * set.cam0_from_board[0];
  for (size_t i = 0; i < set.corners_px[1][0].size(); ++i) {
    const Eigen::Vector3d point = BoardCorners(set.board)[i];
    const auto pixel = Project(set.rig.cam1.intrinsics, cam1_from_board * point);
    ASSERT_TRUE(pixel.has_value());
    EXPECT_LT((*pixel - set.corners_px[1][0][i]).norm(), 1e-9);
    EXPECT_TRUE(InAnnulus(set.cameras[0], set.corners_px[0][0][i]));
  }
}

TEST(CityBlock, LoopIsClosedSmoothAndOfItsLength) {
  const CityBlockLoop loop(100.0);
  EXPECT_NEAR(loop.core_half_size().x(), 2.0 * loop.core_half_size().y(), 1e-12);
  Eigen::Vector2d start, start_outward, end, end_outward;
  loop.At(0.0, &start, &start_outward);
  loop.At(100.0, &end, &end_outward);
  EXPECT_LT((start - end).norm(), 1e-9);
  EXPECT_NEAR(start.y(), -loop.core_half_size().y() - CityBlockLoop::kPathOffsetM, 1e-12);
  double length = 0.0;
  Eigen::Vector2d previous = start;
  for (int i = 1; i <= 10000; ++i) {
    Eigen::Vector2d point, outward;
    loop.At(i * 0.01, &point, &outward);
    EXPECT_LT((point - previous).norm(), 0.0101);  // no jump
    // kPathOffsetM from the core rectangle, the normal pointing away from it.
    const Eigen::Vector2d nearest = point.cwiseMax(-loop.core_half_size())
                                         .cwiseMin(loop.core_half_size());
    EXPECT_NEAR((point - nearest).norm(), CityBlockLoop::kPathOffsetM, 1e-9);
    EXPECT_NEAR(outward.dot((point - nearest).normalized()), 1.0, 1e-9);
    length += (point - previous).norm();
    previous = point;
  }
  EXPECT_NEAR(length, 100.0, 1e-3);
  EXPECT_THROW(CityBlockLoop(20.0), InvalidArgument);
}

// A short city-block loop at a tiny size: two laps, with the lighting changing between them.
TEST(CityBlock, LapsRevisitPlacesUnderOtherLight) {
  StereoSequenceOptions options;
  options.environment = StereoSequenceOptions::Environment::kCityBlock;
  options.path_length_m = 40.0;
  options.num_laps = 2;
  options.num_frames = 8;
  options.lighting_change = true;
  options.width = 96;
  options.height = 72;
  options.render.supersampling = 1;
  const StereoSequence sequence = MakeStereoSequence(options);
  ASSERT_EQ(sequence.world_from_rig.size(), 8u);
  EXPECT_EQ(sequence.laps, (std::vector<int>{0, 0, 0, 0, 1, 1, 1, 1}));
  for (int i = 0; i < 4; ++i) {
    // The same place one lap later, on a line at most 1 m to the side, heading the same way.
    const Rigid3d& first = sequence.world_from_rig[i];
    const Rigid3d& second = sequence.world_from_rig[i + 4];
    const double apart_m = (first.translation - second.translation).norm();
    EXPECT_LT(apart_m, 1.0);
    EXPECT_LT(first.rotation.angularDistance(second.rotation), 0.1);
    // 10 m of path between frames (a chord across a corner is shorter), the sensor at its
    // height.
    const double step_m =
        (sequence.world_from_rig[i + 1].translation - first.translation).head<2>().norm();
    EXPECT_GT(step_m, 6.0);
    EXPECT_LT(step_m, 10.5);
    EXPECT_NEAR(first.translation.z(), options.sensor_height_m, 1e-9);
  }
  // Lap 1 is LapLighting(1), the dim evening: darker by about its gain.
  double mean[2] = {0.0, 0.0};
  for (int i = 0; i < 4; ++i) {
    mean[0] += cv::mean(sequence.images[0][i])[1];
    mean[1] += cv::mean(sequence.images[0][i + 4])[1];
  }
  EXPECT_LT(mean[1], 0.85 * mean[0]);
  EXPECT_GT(mean[1], 0.4 * mean[0]);
}

TEST(CityBlock, OptionsAreChecked) {
  StereoSequenceOptions options;
  options.environment = StereoSequenceOptions::Environment::kCityBlock;
  EXPECT_THROW(options.Check(), InvalidArgument);  // 6 m: too short a loop
  options.path_length_m = 100.0;
  options.Check();
  options.num_laps = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = StereoSequenceOptions();
  options.num_laps = 2;  // the room's path is no loop
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = StereoSequenceOptions();
  options.motion_blur_exposure_s = -0.01;
  EXPECT_THROW(options.Check(), InvalidArgument);
  EXPECT_EQ(LapLighting(0).gain, 1.0);
  EXPECT_NE(LapLighting(1).gain, LapLighting(2).gain);
}

// The room and street sequences render exactly as they did before the city block, lighting and
// motion blur were added (digests recorded with the renderer of main at 71167e3, on this
// platform's build). A deliberate change of the renderer's output updates them.
TEST(Presets, ExistingSequencesRenderAsBefore) {
  const struct {
    StereoSequenceOptions::Environment environment;
    int supersampling;
    uint64_t digest;
  } cases[] = {{StereoSequenceOptions::Environment::kRoom, 4, 0x24ed4761d1ca3630ull},
               {StereoSequenceOptions::Environment::kStreet, 2, 0xc49e5886fb8edb11ull}};
  for (const auto& c : cases) {
    StereoSequenceOptions options;
    options.environment = c.environment;
    options.num_frames = 3;
    options.width = 160;
    options.height = 120;
    options.render.supersampling = c.supersampling;
    options.render.noise_sigma = 1.0;
    const StereoSequence sequence = MakeStereoSequence(options);
    const uint64_t digest = Digest(sequence.images[1], Digest(sequence.images[0]));
    EXPECT_EQ(digest, c.digest) << std::hex << "0x" << digest;
  }
}

}  // namespace
}  // namespace omnirig::synth
