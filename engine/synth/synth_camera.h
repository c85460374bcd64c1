#pragma once
// The synthetic catadioptric camera: a unified-model camera (engine/geometry/unified_camera.h)
// plus the image of its mirror, a disk of radius rim_radius_px around (u0, v0) with a central
// hole of radius hole_radius_px where a real mirror shows the camera itself. Pixels outside the
// disk and inside the hole are dark in every render.
//
// Frame convention of an upright sensor (the paper's Fig. 1): the camera's +z axis points
// down, from the mirror towards the camera below it. Bearings near +z image near the centre
// (inside the hole), the horizon (z = 0) images at |m| = 1/xi on the normalised plane, and the
// rim sees somewhat above the horizon. WorldFromUprightCamera() builds such a pose in a z-up
// world.

#include <optional>

#include <Eigen/Core>

#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"

namespace omnirig::synth {

struct SynthCamera {
  CameraModel model;
  double rim_radius_px = 0.0;   // outer edge of the mirror disk, around (u0, v0)
  double hole_radius_px = 0.0;  // central hole, around (u0, v0)

  // Throws InvalidArgument when the intrinsics are invalid, the radii are not
  // 0 <= hole < rim, or the rim circle cannot be lifted (outside the model's valid domain).
  void Check() const;
};

// A hyperbolic-mirror-like camera: xi = 0.94, gamma_u = 0.33 * min(width, height) (253 px at
// 1024x768), gamma_v 0.5% larger, principal point a few pixels off the image centre, k1 = -0.06,
// k2 = 0.012, k3 = 4e-4, k4 = -3e-4, k5 = 0, alpha = 0; rim radius 0.48 * min(width, height)
// (bearings up to 20 degrees above the horizon), hole radius 0.115 * min(width, height)
// (bearings within 37 degrees of the downward axis are hidden).
SynthCamera DefaultCamera(int width = 1024, int height = 768);

// A second camera of the same make for stereo rigs: intrinsics a little different from
// DefaultCamera() (as two real units would be), same image size, same mirror radii.
SynthCamera DefaultSecondCamera(int width = 1024, int height = 768);

// A paracatadioptric camera (parabolic mirror, telecentric lens): xi = 1, gamma_u = 0.4 *
// min(width, height) (410 px at 1280x1024), no distortion, principal point a few pixels off the
// image centre; rim radius 0.48 * min(width, height) (10 degrees above the horizon) and a large
// central hole of 0.15 * min(width, height) where the mirror shows the camera itself.
SynthCamera ParabolicCamera(int width = 1280, int height = 1024);

// True when `pixel` lies in the mirror annulus, at least margin_px inside the rim and outside
// the hole.
bool InAnnulus(const SynthCamera& camera, const Eigen::Vector2d& pixel, double margin_px = 0.0);

// The pixel of a point in the camera frame when it projects inside the annulus (with margin);
// nullopt otherwise.
std::optional<Eigen::Vector2d> ProjectVisible(const SynthCamera& camera,
                                              const Eigen::Vector3d& point_in_cam,
                                              double margin_px = 0.0);

// The angles (radians from the camera's +z axis) of the bearings seen at the hole and rim
// circles, the smallest over azimuth for the rim and the largest for the hole, so that any
// bearing between them (and clear of the margins) images inside the annulus.
struct AnnulusBand {
  double hole_angle_rad = 0.0;
  double rim_angle_rad = 0.0;
};
AnnulusBand ComputeAnnulusBand(const SynthCamera& camera);

// Pose of an upright sensor (camera +z pointing down) at `position_m` in a z-up world, turned by
// yaw_rad about the world's z axis: the camera's x axis is the world's x axis rotated by yaw.
Rigid3d WorldFromUprightCamera(const Eigen::Vector3d& position_m, double yaw_rad);

}  // namespace omnirig::synth
