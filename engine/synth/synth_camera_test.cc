#include "engine/synth/synth_camera.h"

#include <cmath>

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig::synth {
namespace {

TEST(SynthCamera, DefaultCameraIsHyperbolicLike) {
  const SynthCamera camera = DefaultCamera();
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  EXPECT_EQ(camera.model.width, 1024);
  EXPECT_EQ(camera.model.height, 768);
  EXPECT_GE(k.xi(), 0.9);
  EXPECT_LE(k.xi(), 1.0);
  EXPECT_NE(k.k(1), 0.0);
  EXPECT_NE(k.k(2), 0.0);
  EXPECT_NE(k.k(3), 0.0);
  EXPECT_EQ(k.k(5), 0.0);
  // The mirror disk lies inside the image.
  EXPECT_GT(k.v0() - camera.rim_radius_px, 0.0);
  EXPECT_LT(k.v0() + camera.rim_radius_px, camera.model.height - 1.0);
  EXPECT_NO_THROW(DefaultSecondCamera(640, 480).Check());
  EXPECT_NE(DefaultSecondCamera().model.intrinsics.params, k.params);
}

TEST(SynthCamera, AnnulusBandSpansTheHorizon) {
  const AnnulusBand band = ComputeAnnulusBand(DefaultCamera());
  // The hole hides the steep downward view, the rim sees above the horizon.
  EXPECT_GT(band.hole_angle_rad, 0.5);
  EXPECT_LT(band.hole_angle_rad, 0.9);
  EXPECT_GT(band.rim_angle_rad, M_PI / 2 + 0.2);
  EXPECT_LT(band.rim_angle_rad, M_PI / 2 + 0.5);
}

TEST(SynthCamera, InAnnulusAndProjectVisible) {
  const SynthCamera camera = DefaultCamera(640, 480);
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  const Eigen::Vector2d centre(k.u0(), k.v0());
  EXPECT_FALSE(InAnnulus(camera, centre));
  EXPECT_TRUE(InAnnulus(camera, centre + Eigen::Vector2d(camera.hole_radius_px + 2, 0)));
  EXPECT_FALSE(InAnnulus(camera, centre + Eigen::Vector2d(camera.hole_radius_px + 2, 0), 5.0));
  EXPECT_FALSE(InAnnulus(camera, centre + Eigen::Vector2d(0, camera.rim_radius_px + 1)));
  // A point on the horizon is visible; one straight below (the camera itself) is not.
  EXPECT_TRUE(ProjectVisible(camera, Eigen::Vector3d(2.0, 1.0, 0.0)).has_value());
  EXPECT_FALSE(ProjectVisible(camera, Eigen::Vector3d(0.01, 0.0, 1.0)).has_value());
}

TEST(SynthCamera, CheckRejectsBadRadii) {
  SynthCamera camera = DefaultCamera(640, 480);
  camera.hole_radius_px = camera.rim_radius_px + 1;
  EXPECT_THROW(camera.Check(), InvalidArgument);
  camera = DefaultCamera(640, 480);
  camera.rim_radius_px = 1e6;  // beyond the lifting domain
  EXPECT_THROW(camera.Check(), InvalidArgument);
  EXPECT_THROW(DefaultCamera(4, 4), InvalidArgument);
}

TEST(SynthCamera, UprightCameraLooksDown) {
  const Rigid3d world_from_cam = WorldFromUprightCamera(Eigen::Vector3d(1, 2, 1), 0.5);
  const Eigen::Vector3d down_in_world = world_from_cam.rotation * Eigen::Vector3d::UnitZ();
  EXPECT_NEAR(down_in_world.z(), -1.0, 1e-12);
  const Eigen::Vector3d x_in_world = world_from_cam.rotation * Eigen::Vector3d::UnitX();
  EXPECT_NEAR(x_in_world.x(), std::cos(0.5), 1e-12);
  EXPECT_NEAR(x_in_world.y(), std::sin(0.5), 1e-12);
}

}  // namespace
}  // namespace omnirig::synth
