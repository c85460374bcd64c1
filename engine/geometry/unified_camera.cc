#include "engine/geometry/unified_camera.h"

#include "engine/util/check.h"

namespace omnirig {

void UnifiedIntrinsics::Check() const {
  for (int i = 0; i < kNumParams; ++i) {
    OMNIRIG_CHECK(std::isfinite(params[i]), "intrinsic " << kNames[i] << " is not finite");
  }
  OMNIRIG_CHECK(xi() >= 0.0, "xi must be >= 0, got " << xi());
  OMNIRIG_CHECK(gamma_u() > 0.0 && gamma_v() > 0.0,
                "generalised focal lengths must be positive, got gamma_u=" << gamma_u()
                                                                           << " gamma_v="
                                                                           << gamma_v());
}

std::optional<Eigen::Vector2d> Project(const UnifiedIntrinsics& intrinsics,
                                       const Eigen::Vector3d& point_in_cam) {
  Eigen::Vector2d pixel;
  if (!Project(intrinsics.params.data(), point_in_cam, &pixel)) return std::nullopt;
  return pixel;
}

std::optional<Eigen::Vector2d> Undistort(const UnifiedIntrinsics& intrinsics,
                                         const Eigen::Vector2d& distorted) {
  Eigen::Vector2d undistorted;
  if (!Undistort(intrinsics.params.data(), distorted, &undistorted)) return std::nullopt;
  return undistorted;
}

std::optional<Eigen::Vector3d> Lift(const UnifiedIntrinsics& intrinsics,
                                    const Eigen::Vector2d& pixel) {
  Eigen::Vector3d bearing;
  if (!Lift(intrinsics.params.data(), pixel, &bearing)) return std::nullopt;
  return bearing;
}

}  // namespace omnirig
