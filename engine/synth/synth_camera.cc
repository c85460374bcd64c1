#include "engine/synth/synth_camera.h"

#include <algorithm>
#include <cmath>

#include "engine/util/check.h"

namespace omnirig::synth {
namespace {

constexpr int kBandAzimuths = 360;

SynthCamera MakeCamera(int width, int height, const std::array<double, 11>& relative_params) {
  OMNIRIG_CHECK(width >= 16 && height >= 16,
                "image size must be at least 16 x 16, got " << width << " x " << height);
  const double size = std::min(width, height);
  SynthCamera camera;
  camera.model.width = width;
  camera.model.height = height;
  UnifiedIntrinsics& k = camera.model.intrinsics;
  k.params = relative_params;
  // Focal lengths and principal point offsets scale with the image; the rest is unitless.
  k.gamma_u() = relative_params[UnifiedIntrinsics::kGammaU] * size;
  k.gamma_v() = relative_params[UnifiedIntrinsics::kGammaV] * size;
  k.u0() = 0.5 * width - 0.5 + relative_params[UnifiedIntrinsics::kU0] * size;
  k.v0() = 0.5 * height - 0.5 + relative_params[UnifiedIntrinsics::kV0] * size;
  camera.rim_radius_px = 0.48 * size;
  camera.hole_radius_px = 0.115 * size;
  camera.Check();
  return camera;
}

Eigen::Vector2d CirclePoint(const SynthCamera& camera, double radius_px, double azimuth_rad) {
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  return Eigen::Vector2d(k.u0() + radius_px * std::cos(azimuth_rad),
                         k.v0() + radius_px * std::sin(azimuth_rad));
}

}  // namespace

void SynthCamera::Check() const {
  model.intrinsics.Check();
  OMNIRIG_CHECK(model.width > 0 && model.height > 0,
                "image size must be positive, got " << model.width << " x " << model.height);
  OMNIRIG_CHECK(std::isfinite(rim_radius_px) && std::isfinite(hole_radius_px) &&
                    hole_radius_px >= 0.0 && hole_radius_px < rim_radius_px,
                "mirror radii must satisfy 0 <= hole < rim, got hole=" << hole_radius_px
                                                                       << " rim=" << rim_radius_px);
  // Every pixel inside the rim must lift; checking the rim circle suffices for a monotone
  // distortion (lifting fails first at the largest radii).
  for (int i = 0; i < 64; ++i) {
    const Eigen::Vector2d pixel = CirclePoint(*this, rim_radius_px, 2.0 * M_PI * i / 64);
    OMNIRIG_CHECK(Lift(model.intrinsics, pixel).has_value(),
                  "the mirror rim at pixel (" << pixel.x() << ", " << pixel.y()
                                              << ") is outside the camera model's lifting domain");
  }
}

SynthCamera DefaultCamera(int width, int height) {
  // [xi, gamma_u, gamma_v, du0, dv0, alpha, k1..k5] with focal lengths and principal point
  // offsets relative to min(width, height). gamma = 0.33 puts the rim (0.48) about 20 degrees
  // above the horizon with this distortion, which stays monotone well beyond the rim.
  return MakeCamera(width, height,
                    {0.94, 0.330, 0.3315, 0.0037, -0.0023, 0.0, -0.06, 0.012, 4e-4, -3e-4, 0.0});
}

SynthCamera DefaultSecondCamera(int width, int height) {
  return MakeCamera(width, height,
                    {0.96, 0.334, 0.3352, -0.0029, 0.0031, 0.0, -0.055, 0.010, -2e-4, 3e-4, 0.0});
}

SynthCamera ParabolicCamera(int width, int height) {
  SynthCamera camera =
      MakeCamera(width, height, {1.0, 0.4, 0.4, 0.0041, -0.0027, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0});
  camera.hole_radius_px = 0.15 * std::min(width, height);
  camera.Check();
  return camera;
}

bool InAnnulus(const SynthCamera& camera, const Eigen::Vector2d& pixel, double margin_px) {
  const UnifiedIntrinsics& k = camera.model.intrinsics;
  if (!(pixel.x() >= 0.0 && pixel.y() >= 0.0 && pixel.x() <= camera.model.width - 1.0 &&
        pixel.y() <= camera.model.height - 1.0)) {
    return false;
  }
  const double r = std::hypot(pixel.x() - k.u0(), pixel.y() - k.v0());
  return r >= camera.hole_radius_px + margin_px && r <= camera.rim_radius_px - margin_px;
}

std::optional<Eigen::Vector2d> ProjectVisible(const SynthCamera& camera,
                                              const Eigen::Vector3d& point_in_cam,
                                              double margin_px) {
  const auto pixel = Project(camera.model.intrinsics, point_in_cam);
  if (!pixel || !InAnnulus(camera, *pixel, margin_px)) return std::nullopt;
  return pixel;
}

AnnulusBand ComputeAnnulusBand(const SynthCamera& camera) {
  AnnulusBand band;
  band.rim_angle_rad = M_PI;
  band.hole_angle_rad = 0.0;
  for (int i = 0; i < kBandAzimuths; ++i) {
    const double azimuth = 2.0 * M_PI * i / kBandAzimuths;
    const auto rim =
        Lift(camera.model.intrinsics, CirclePoint(camera, camera.rim_radius_px, azimuth));
    OMNIRIG_CHECK(rim.has_value(), "the mirror rim does not lift");
    band.rim_angle_rad = std::min(band.rim_angle_rad, std::acos(std::clamp(rim->z(), -1.0, 1.0)));
    const auto hole =
        Lift(camera.model.intrinsics, CirclePoint(camera, camera.hole_radius_px, azimuth));
    OMNIRIG_CHECK(hole.has_value(), "the mirror hole does not lift");
    band.hole_angle_rad =
        std::max(band.hole_angle_rad, std::acos(std::clamp(hole->z(), -1.0, 1.0)));
  }
  return band;
}

Rigid3d WorldFromUprightCamera(const Eigen::Vector3d& position_m, double yaw_rad) {
  const Eigen::Quaterniond yaw(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()));
  const Eigen::Quaterniond flip(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()));
  return Rigid3d(yaw * flip, position_m);
}

}  // namespace omnirig::synth
