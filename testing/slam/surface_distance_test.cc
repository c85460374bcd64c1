#include "testing/slam/surface_distance.h"

#include <cmath>

#include <gtest/gtest.h>

namespace omnirig::slam {
namespace {

Rigid3d At(double x, double y, double z) {
  return Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(x, y, z));
}

TEST(DistanceToSceneSurface, BoxFromInsideCylinderAndPlane) {
  synth::Scene scene;
  synth::TextureSpec plain;
  plain.style = synth::TextureSpec::Style::kPlain;
  plain.texel_size_m = 0.05;
  scene.AddBox(At(0, 0, 1.4), Eigen::Vector3d(10, 7, 2.8), plain, "room");
  scene.AddCylinder(At(1.5, -1.7, 0), 0.2, 2.8, plain, "pillar");
  // Inside the room, 1 m above the floor and far from the walls: the floor is nearest.
  EXPECT_NEAR(DistanceToSceneSurface(scene, Eigen::Vector3d(0, 0, 1.0)), 1.0, 1e-12);
  // 0.3 m from the pillar's axis: 0.1 m from its side.
  EXPECT_NEAR(DistanceToSceneSurface(scene, Eigen::Vector3d(1.5, -1.4, 1.4)), 0.1, 1e-12);
  // On a wall.
  EXPECT_NEAR(DistanceToSceneSurface(scene, Eigen::Vector3d(5.0, 0.5, 1.4)), 0.0, 1e-12);
  synth::Scene street;
  street.AddPlane(At(0, 0, 0), 4, 2, plain, "ground");
  EXPECT_NEAR(DistanceToSceneSurface(street, Eigen::Vector3d(0.5, 0.5, -0.25)), 0.25, 1e-12);
  EXPECT_NEAR(DistanceToSceneSurface(street, Eigen::Vector3d(3, 0, 0)), 1.0, 1e-12);
}

TEST(RangeToSceneSurface, FirstHitAlongTheRay) {
  synth::Scene scene;
  synth::TextureSpec plain;
  plain.style = synth::TextureSpec::Style::kPlain;
  plain.texel_size_m = 0.05;
  scene.AddBox(At(0, 0, 1.4), Eigen::Vector3d(10, 7, 2.8), plain, "room");
  scene.AddCylinder(At(1.5, 0, 0), 0.2, 2.8, plain, "pillar");
  const Eigen::Vector3d origin(0, 0, 1.0);
  // Straight down to the floor, up to the ceiling, along +y to the wall.
  EXPECT_NEAR(RangeToSceneSurface(scene, origin, Eigen::Vector3d(0, 0, -1)), 1.0, 1e-12);
  EXPECT_NEAR(RangeToSceneSurface(scene, origin, Eigen::Vector3d(0, 0, 1)), 1.8, 1e-12);
  EXPECT_NEAR(RangeToSceneSurface(scene, origin, Eigen::Vector3d(0, 1, 0)), 3.5, 1e-12);
  // Along +x the pillar's side (1.3 m) comes before the wall (5 m).
  EXPECT_NEAR(RangeToSceneSurface(scene, origin, Eigen::Vector3d(1, 0, 0)), 1.3, 1e-12);
  // Obliquely to the floor: 1 / cos(60 deg).
  const Eigen::Vector3d oblique(0, std::sin(M_PI / 3), -std::cos(M_PI / 3));
  EXPECT_NEAR(RangeToSceneSurface(scene, origin, oblique), 2.0, 1e-12);
  synth::Scene ground;
  ground.AddPlane(At(0, 0, 0), 4, 2, plain, "ground");
  EXPECT_NEAR(RangeToSceneSurface(ground, origin, Eigen::Vector3d(0, 0, -1)), 1.0, 1e-12);
  // Missing the plane, or looking away from it.
  EXPECT_TRUE(
      std::isinf(RangeToSceneSurface(ground, Eigen::Vector3d(3, 0, 1), Eigen::Vector3d(0, 0, -1))));
  EXPECT_TRUE(std::isinf(RangeToSceneSurface(ground, origin, Eigen::Vector3d(0, 0, 1))));
}

}  // namespace
}  // namespace omnirig::slam
