#include "engine/synth/scene.h"

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "engine/util/check.h"

namespace omnirig::synth {
namespace {

TEST(Scene, BoardCornersAreRowMajor) {
  CheckerboardSpec spec;
  spec.cols = 4;
  spec.rows = 3;
  spec.square_size_m = 0.05;
  const auto corners = BoardCorners(spec);
  ASSERT_EQ(corners.size(), 12u);
  EXPECT_EQ(corners[0], Eigen::Vector3d(0, 0, 0));
  EXPECT_NEAR(corners[1].x(), 0.05, 1e-15);
  EXPECT_NEAR(corners[4].y(), 0.05, 1e-15);
  EXPECT_NEAR(corners[11].x(), 0.15, 1e-15);
  EXPECT_NEAR(corners[11].y(), 0.10, 1e-15);
  const auto outline = BoardOutline(spec);
  EXPECT_NEAR(outline[2].x() - outline[0].x(), spec.width_m(), 1e-12);
  EXPECT_NEAR(outline[2].y() - outline[0].y(), spec.height_m(), 1e-12);
  spec.cols = 1;
  EXPECT_THROW(BoardCorners(spec), InvalidArgument);
}

TEST(Scene, TexturesAreDeterministicAndRich) {
  TextureSpec spec;
  spec.seed = 3;
  const cv::Mat a = MakeTexture(spec, 1.0, 0.5);
  const cv::Mat b = MakeTexture(spec, 1.0, 0.5);
  EXPECT_EQ(a.cols, 200);
  EXPECT_EQ(a.rows, 100);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  spec.seed = 4;
  EXPECT_GT(cv::norm(a, MakeTexture(spec, 1.0, 0.5), cv::NORM_L1), 0.0);
  cv::Scalar mean, stddev;
  cv::meanStdDev(a, mean, stddev);
  EXPECT_GT(stddev[0], 30.0);  // high contrast for feature detectors
  spec.style = TextureSpec::Style::kSoft;
  cv::meanStdDev(MakeTexture(spec, 1.0, 0.5), mean, stddev);
  EXPECT_LT(stddev[0], 20.0);
  // Huge faces are coarsened, not allocated at full resolution.
  spec.style = TextureSpec::Style::kPlain;
  EXPECT_LE(MakeTexture(spec, 100.0, 3.0).cols, 2048);
}

TEST(Scene, AddPrimitives) {
  Scene scene;
  TextureSpec texture;
  EXPECT_EQ(scene.AddPlane(Rigid3d(), 1.0, 2.0, texture), 0);
  EXPECT_EQ(scene.AddBox(Rigid3d(), Eigen::Vector3d(0.2, 0.3, 0.4), texture), 1);
  EXPECT_EQ(scene.AddCylinder(Rigid3d(), 0.1, 1.0, texture), 2);
  EXPECT_EQ(scene.AddCheckerboard(CheckerboardSpec(), Rigid3d()), 3);
  EXPECT_EQ(scene.textures(0).size(), 1u);
  EXPECT_EQ(scene.textures(1).size(), 6u);
  EXPECT_EQ(scene.textures(2).size(), 3u);
  EXPECT_TRUE(scene.textures(3).empty());
  EXPECT_STREQ(KindName(scene.primitives()[2].kind), "cylinder");
  EXPECT_THROW(scene.AddPlane(Rigid3d(), -1.0, 1.0, texture), InvalidArgument);
  EXPECT_THROW(scene.SetBoardPose(0, Rigid3d()), InvalidArgument);
  scene.SetBoardPose(3, Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 2, 3)));
  EXPECT_EQ(scene.primitives()[3].world_from_local.translation, Eigen::Vector3d(1, 2, 3));
}

}  // namespace
}  // namespace omnirig::synth
