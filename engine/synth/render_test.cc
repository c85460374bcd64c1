#include "engine/synth/render.h"

#include <cmath>
#include <iostream>
#include <optional>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "engine/synth/presets.h"
#include "engine/util/check.h"

namespace omnirig::synth {
namespace {

// Small images keep these tests fast under the sanitizers.
constexpr int kWidth = 160;
constexpr int kHeight = 120;

Scene BoardScene(const SynthCamera& camera, Rigid3d* cam_from_board) {
  CheckerboardSpec board;
  board.cols = 5;
  board.rows = 4;
  board.square_size_m = 0.05;
  BoardPoseOptions poses;
  poses.min_square_px = 2.0;
  poses.min_margin_px = 2.0;
  *cam_from_board = SampleBoardPose({camera}, {Rigid3d()}, board, poses, 0, 1, 5);
  Scene scene = MakeCalibrationBackground(1);
  scene.AddCheckerboard(board, *cam_from_board);
  return scene;
}

TEST(Render, DarkOutsideTheRimAndInsideTheHole) {
  const SynthCamera camera = DefaultCamera(kWidth, kHeight);
  Rigid3d cam_from_board;
  const Scene scene = BoardScene(camera, &cam_from_board);
  RenderOptions options;
  options.supersampling = 2;
  const cv::Mat image = Render(scene, camera, Rigid3d(), options);
  ASSERT_EQ(image.type(), CV_8UC3);
  ASSERT_EQ(image.cols, kWidth);
  ASSERT_EQ(image.rows, kHeight);
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  int dark = 0, lit = 0;
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      const double r = std::hypot(u - k.u0(), v - k.v0());
      const cv::Vec3b pixel = image.at<cv::Vec3b>(v, u);
      if (r > camera.rim_radius_px + 1.0 || r < camera.hole_radius_px - 1.0) {
        EXPECT_EQ(pixel, cv::Vec3b::all(static_cast<uint8_t>(kDarkLevel))) << u << "," << v;
        ++dark;
      } else if (r < camera.rim_radius_px - 1.0 && r > camera.hole_radius_px + 1.0) {
        // The room's walls are at least 100 grey levels bright.
        EXPECT_GT(pixel[1], 20) << u << "," << v;
        ++lit;
      }
    }
  }
  EXPECT_GT(dark, 1000);
  EXPECT_GT(lit, 5000);
}

TEST(Render, DeterministicForASeedAndAnyThreadCount) {
  const SynthCamera camera = DefaultCamera(kWidth, kHeight);
  Rigid3d cam_from_board;
  const Scene scene = BoardScene(camera, &cam_from_board);
  RenderOptions options;
  options.supersampling = 2;
  options.noise_sigma = 3.0;
  options.blur_sigma_px = 0.5;
  options.vignetting = 0.2;
  options.seed = 11;
  options.num_threads = 1;
  const Renderer renderer(camera);
  const cv::Mat a = renderer.Render(scene, Rigid3d(), options);
  options.num_threads = 3;
  const cv::Mat b = renderer.Render(scene, Rigid3d(), options);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  options.seed = 12;
  EXPECT_GT(cv::norm(a, renderer.Render(scene, Rigid3d(), options), cv::NORM_L1), 0.0);
}

TEST(Render, GrayscaleAndBackground) {
  const SynthCamera camera = DefaultCamera(kWidth, kHeight);
  Scene empty;
  empty.SetBackgroundRgb(Eigen::Vector3d(0.5, 0.5, 0.5));
  RenderOptions options;
  options.supersampling = 1;
  options.grayscale = true;
  const cv::Mat image = Render(empty, camera, Rigid3d(), options);
  ASSERT_EQ(image.type(), CV_8UC1);
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  const int u = static_cast<int>(k.u0() + 0.5 * (camera.rim_radius_px + camera.hole_radius_px));
  EXPECT_NEAR(image.at<uint8_t>(static_cast<int>(k.v0()), u), 127.5, 1.0);
}

// A board of 3 x 3 inner corners, 0.1 m squares.
CheckerboardSpec SmallBoard() {
  CheckerboardSpec board;
  board.cols = 3;
  board.rows = 3;
  board.square_size_m = 0.1;
  return board;
}

TEST(Render, BoardSquaresAreBlackAndWhiteWhereTheyProject) {
  const SynthCamera camera = DefaultCamera(320, 240);
  const CheckerboardSpec board = SmallBoard();
  // A board 0.6 m away on the horizon, facing the camera (printed side towards it).
  const Eigen::Matrix3d board_axes_in_cam =
      (Eigen::Matrix3d() << 0, 0, 1, 1, 0, 0, 0, 1, 0).finished();  // columns: x, y, z of board
  const Eigen::Vector3d centre_in_board(0.1, 0.1, 0.0);
  const Rigid3d cam_from_board(
      Eigen::Quaterniond(board_axes_in_cam),
      Eigen::Vector3d(0.6, 0.0, 0.0) - board_axes_in_cam * centre_in_board);
  Scene scene;
  scene.AddCheckerboard(board, cam_from_board);
  RenderOptions options;
  options.grayscale = true;
  const cv::Mat image = Render(scene, camera, Rigid3d(), options);
  // The centres of square (-1, -1) (black) and (0, -1) (white).
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  const auto black = Project(k, cam_from_board * Eigen::Vector3d(-0.05, -0.05, 0));
  const auto white = Project(k, cam_from_board * Eigen::Vector3d(0.05, -0.05, 0));
  ASSERT_TRUE(black && white);
  EXPECT_NEAR(image.at<uint8_t>(cvRound(black->y()), cvRound(black->x())), kBoardBlackLevel, 2.0);
  EXPECT_NEAR(image.at<uint8_t>(cvRound(white->y()), cvRound(white->x())), kBoardWhiteLevel, 2.0);
  // Seen from behind, the board is plain grey.
  const Eigen::Quaterniond half_turn(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()));
  const Rigid3d flipped = cam_from_board * Rigid3d(half_turn, Eigen::Vector3d(0.2, 0, 0));
  scene.SetBoardPose(0, flipped);
  const cv::Mat back = Render(scene, camera, Rigid3d(), options);
  EXPECT_NEAR(back.at<uint8_t>(cvRound(black->y()), cvRound(black->x())), 110.0, 2.0);
}

// Grey level of the board pattern at board point (x, y), as the renderer defines it.
double BoardLevel(const CheckerboardSpec& board, double x, double y) {
  const double s = board.square_size_m;
  if (x < -s || y < -s || x >= board.cols * s || y >= board.rows * s) return kBoardWhiteLevel;
  const long parity = static_cast<long>(std::floor(x / s)) + static_cast<long>(std::floor(y / s));
  return parity % 2 == 0 ? kBoardBlackLevel : kBoardWhiteLevel;
}

// Board coordinates of the ray through `pixel`, or nullopt when it misses the board plane.
std::optional<Eigen::Vector2d> BoardPoint(const SynthCamera& camera, const Rigid3d& board_from_cam,
                                          const Eigen::Vector2d& pixel) {
  const Eigen::Vector3d d = board_from_cam.rotation * *Lift(camera.model.intrinsics, pixel);
  const Eigen::Vector3d& o = board_from_cam.translation;
  const double t = -o.z() / d.z();
  if (t <= 0.0) return std::nullopt;
  return Eigen::Vector2d(o.x() + t * d.x(), o.y() + t * d.y());
}

// The board's mean grey level over pixel (u, v) by brute force: 64 x 64 jittered samples, each
// lifted exactly with Lift() and intersected with the board plane; nullopt when one misses it.
std::optional<double> BruteForceLevel(const SynthCamera& camera, const Rigid3d& board_from_cam,
                                      const CheckerboardSpec& board, int u, int v, cv::RNG* rng) {
  double sum = 0.0;
  for (int a = 0; a < 64; ++a) {
    for (int b = 0; b < 64; ++b) {
      const auto point = BoardPoint(camera, board_from_cam,
                                    Eigen::Vector2d(u - 0.5 + (a + rng->uniform(0.0, 1.0)) / 64,
                                                    v - 0.5 + (b + rng->uniform(0.0, 1.0)) / 64));
      if (!point) return std::nullopt;
      sum += BoardLevel(board, point->x(), point->y());
    }
  }
  return sum / (64 * 64);
}

// Edge pixels of the board against brute force (BruteForceLevel).
TEST(Render, BoardEdgesAreExactlyAreaSampled) {
  const SynthCamera camera = DefaultCamera(320, 240);
  const CheckerboardSpec board = SmallBoard();
  const Eigen::Matrix3d board_axes_in_cam =
      Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.3, 1.0, 0.2).normalized()).toRotationMatrix() *
      (Eigen::Matrix3d() << 0, 0, 1, 1, 0, 0, 0, 1, 0).finished();
  const Rigid3d cam_from_board(
      Eigen::Quaterniond(board_axes_in_cam),
      Eigen::Vector3d(0.5, 0.1, -0.1) - board_axes_in_cam * Eigen::Vector3d(0.1, 0.1, 0.0));
  const Rigid3d board_from_cam = cam_from_board.Inverse();
  Scene scene;
  scene.AddCheckerboard(board, cam_from_board);
  RenderOptions options;
  options.grayscale = true;
  options.supersampling = 1;  // the board does not depend on it
  const cv::Mat image = Render(scene, camera, Rigid3d(), options);
  const double s = board.square_size_m;
  cv::RNG rng(4);
  int checked = 0;
  double sum_abs = 0.0;
  for (int v = 0; v < image.rows && checked < 60; ++v) {
    for (int u = 0; u < image.cols && checked < 60; ++u) {
      const double level = image.at<uint8_t>(v, u);
      if (level < kBoardBlackLevel + 10 || level > kBoardWhiteLevel - 10) continue;
      if (!InAnnulus(camera, Eigen::Vector2d(u, v), 2.0)) continue;
      // Edge pixels inside the squares, away from the board's outline.
      const auto centre = BoardPoint(camera, board_from_cam, Eigen::Vector2d(u, v));
      if (!centre || centre->minCoeff() < -0.9 * s || centre->x() > (board.cols - 0.1) * s ||
          centre->y() > (board.rows - 0.1) * s) {
        continue;
      }
      const std::optional<double> expected =
          BruteForceLevel(camera, board_from_cam, board, u, v, &rng);
      ASSERT_TRUE(expected.has_value());
      EXPECT_NEAR(level, *expected, 1.5) << "pixel " << u << ", " << v;
      sum_abs += std::abs(level - *expected);
      ++checked;
    }
  }
  std::cout << checked << " edge pixels, mean abs difference " << sum_abs / checked
            << " grey levels\n";
  ASSERT_GT(checked, 30);
  EXPECT_LT(sum_abs / checked, 0.6);  // 8-bit rounding alone gives 0.25
}

// A closed box of plain grey around the camera (camera frame = world, +z = the floor side the
// mirror sees).
Scene PlainBox() {
  TextureSpec plain;
  plain.style = TextureSpec::Style::kPlain;
  Scene scene;
  scene.AddBox(Rigid3d(), Eigen::Vector3d(8.0, 8.0, 2.0), plain, "box");
  return scene;
}

// The pixel seeing `point_in_cam`, checked to lie well inside the annulus.
cv::Point PixelOf(const SynthCamera& camera, const Eigen::Vector3d& point_in_cam) {
  const auto pixel = Project(camera.model.intrinsics, point_in_cam);
  EXPECT_TRUE(pixel && InAnnulus(camera, *pixel, 3.0));
  return pixel ? cv::Point(cvRound(pixel->x()), cvRound(pixel->y())) : cv::Point(0, 0);
}

TEST(Render, LightingScalesFacesByGainTintAndSun) {
  const SynthCamera camera = DefaultCamera(kWidth, kHeight);
  const Scene scene = PlainBox();
  RenderOptions options;
  options.supersampling = 1;
  const Renderer renderer(camera);
  const cv::Mat neutral = renderer.Render(scene, Rigid3d(), options);
  options.lighting = Lighting();  // the default changes nothing
  EXPECT_EQ(cv::norm(neutral, renderer.Render(scene, Rigid3d(), options), cv::NORM_INF), 0.0);
  options.lighting.gain = 0.8;
  options.lighting.tint_rgb = Eigen::Vector3d(1.0, 0.5, 0.25);
  options.lighting.sun_in_world = Eigen::Vector3d(0.0, 0.0, -2.0);  // lights the +z face
  options.lighting.sun_share = 0.5;
  const cv::Mat lit = renderer.Render(scene, Rigid3d(), options);
  // The floor faces the sun: factor 0.5 + 2 * 0.5 * 1; walls are side-on: 0.5.
  const cv::Point floor = PixelOf(camera, Eigen::Vector3d(3.0, 0.5, 1.0));
  const cv::Point wall = PixelOf(camera, Eigen::Vector3d(4.0, 0.5, 0.3));
  EXPECT_EQ(neutral.at<cv::Vec3b>(floor), cv::Vec3b(160, 160, 160));
  const cv::Vec3b floor_bgr = lit.at<cv::Vec3b>(floor), wall_bgr = lit.at<cv::Vec3b>(wall);
  EXPECT_NEAR(floor_bgr[2], 160 * 0.8 * 1.5, 1.0);
  EXPECT_NEAR(floor_bgr[1], 160 * 0.8 * 1.5 * 0.5, 1.0);
  EXPECT_NEAR(floor_bgr[0], 160 * 0.8 * 1.5 * 0.25, 1.0);
  EXPECT_NEAR(wall_bgr[2], 160 * 0.8 * 0.5, 1.0);
  options.lighting.gain = 0.0;
  EXPECT_THROW(renderer.Render(scene, Rigid3d(), options), InvalidArgument);
}

TEST(Render, MotionBlurAveragesTheExposuresPoses) {
  const SynthCamera camera = DefaultCamera(kWidth, kHeight);
  const Scene scene = MakeRoomScene(2);
  RenderOptions options;
  options.supersampling = 1;
  const Renderer renderer(camera);
  const Rigid3d a = WorldFromUprightCamera(Eigen::Vector3d(0.0, 0.0, 1.0), 0.0).Inverse();
  const Rigid3d b = WorldFromUprightCamera(Eigen::Vector3d(0.0, 0.0, 1.0), 0.05).Inverse();
  const cv::Mat image_a = renderer.Render(scene, a, options);
  const cv::Mat image_b = renderer.Render(scene, b, options);
  EXPECT_EQ(cv::norm(image_a, renderer.Render(scene, std::vector<Rigid3d>{a}, options),
                     cv::NORM_INF),
            0.0);
  const cv::Mat blurred = renderer.Render(scene, std::vector<Rigid3d>{a, b}, options);
  cv::Mat mean;
  cv::addWeighted(image_a, 0.5, image_b, 0.5, 0.0, mean, CV_32F);
  cv::Mat blurred_f;
  blurred.convertTo(blurred_f, CV_32F);
  EXPECT_LE(cv::norm(blurred_f, mean, cv::NORM_INF), 1.0);  // 8-bit rounding of each image
  EXPECT_GT(cv::norm(blurred, image_a, cv::NORM_L1), 0.0);
  EXPECT_THROW(renderer.Render(scene, std::vector<Rigid3d>{}, options), InvalidArgument);
}

TEST(Render, OptionsAreChecked) {
  RenderOptions options;
  options.supersampling = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = RenderOptions();
  options.vignetting = 2.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = RenderOptions();
  options.noise_sigma = -1.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace omnirig::synth
