#include "testing/slam/surface_distance.h"

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

}  // namespace
}  // namespace omnirig::slam
