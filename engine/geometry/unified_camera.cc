#include "engine/geometry/unified_camera.h"

#include <algorithm>

#include <Eigen/LU>

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
  if (!ProjectToPixel(intrinsics.params.data(), point_in_cam.data(), pixel.data())) {
    return std::nullopt;
  }
  return pixel;
}

std::optional<Eigen::Vector2d> ProjectWithJacobian(const UnifiedIntrinsics& intrinsics,
                                                   const Eigen::Vector3d& point_in_cam,
                                                   Eigen::Matrix<double, 2, 3>* d_pixel_d_point) {
  const auto pixel = Project(intrinsics, point_in_cam);
  if (!pixel || d_pixel_d_point == nullptr) return pixel;
  using I = UnifiedIntrinsics;
  const double* p = intrinsics.params.data();
  const double norm = point_in_cam.norm();
  const Eigen::Vector3d s = point_in_cam / norm;
  // d s / d X = (I - s s^T) / |X|
  const Eigen::Matrix3d ds_dX = (Eigen::Matrix3d::Identity() - s * s.transpose()) / norm;
  const double denom = s.z() + p[I::kXi];
  const double x = s.x() / denom, y = s.y() / denom;
  Eigen::Matrix<double, 2, 3> dm_ds;
  dm_ds << 1.0 / denom, 0.0, -s.x() / (denom * denom), 0.0, 1.0 / denom,
      -s.y() / (denom * denom);
  const double rho2 = x * x + y * y;
  const double radial = 1 + p[I::kK1] * rho2 + p[I::kK2] * rho2 * rho2 +
                        p[I::kK5] * rho2 * rho2 * rho2;
  const double dradial_drho2 =
      p[I::kK1] + 2 * p[I::kK2] * rho2 + 3 * p[I::kK5] * rho2 * rho2;
  const double k3 = p[I::kK3], k4 = p[I::kK4];
  Eigen::Matrix2d dmd_dm;
  dmd_dm(0, 0) = radial + x * dradial_drho2 * 2 * x + 2 * k3 * y + k4 * 6 * x;
  dmd_dm(0, 1) = x * dradial_drho2 * 2 * y + 2 * k3 * x + k4 * 2 * y;
  dmd_dm(1, 0) = y * dradial_drho2 * 2 * x + 2 * k4 * y + k3 * 2 * x;
  dmd_dm(1, 1) = radial + y * dradial_drho2 * 2 * y + 2 * k4 * x + k3 * 6 * y;
  Eigen::Matrix2d dp_dmd;
  dp_dmd << p[I::kGammaU], p[I::kGammaU] * p[I::kAlpha], 0.0, p[I::kGammaV];
  *d_pixel_d_point = dp_dmd * dmd_dm * dm_ds * ds_dX;
  return pixel;
}

std::optional<Eigen::Vector2d> Undistort(const UnifiedIntrinsics& intrinsics,
                                         const Eigen::Vector2d& distorted) {
  using I = UnifiedIntrinsics;
  const double* p = intrinsics.params.data();
  Eigen::Vector2d m = distorted;
  for (int iter = 0; iter < 50; ++iter) {
    const double x = m.x(), y = m.y();
    double xd, yd;
    Distort(p, x, y, &xd, &yd);
    const Eigen::Vector2d residual(xd - distorted.x(), yd - distorted.y());
    if (!residual.allFinite()) return std::nullopt;
    if (residual.norm() < 1e-14) return m;
    const double rho2 = x * x + y * y;
    const double radial = 1 + p[I::kK1] * rho2 + p[I::kK2] * rho2 * rho2 +
                          p[I::kK5] * rho2 * rho2 * rho2;
    const double dr = p[I::kK1] + 2 * p[I::kK2] * rho2 + 3 * p[I::kK5] * rho2 * rho2;
    const double k3 = p[I::kK3], k4 = p[I::kK4];
    Eigen::Matrix2d jac;
    jac(0, 0) = radial + 2 * x * x * dr + 2 * k3 * y + 6 * k4 * x;
    jac(0, 1) = 2 * x * y * dr + 2 * k3 * x + 2 * k4 * y;
    jac(1, 0) = 2 * x * y * dr + 2 * k4 * y + 2 * k3 * x;
    jac(1, 1) = radial + 2 * y * y * dr + 2 * k4 * x + 6 * k3 * y;
    const double det = jac.determinant();
    if (!(std::abs(det) > 1e-12)) return std::nullopt;
    m -= jac.inverse() * residual;
  }
  double xd, yd;
  Distort(p, m.x(), m.y(), &xd, &yd);
  if ((Eigen::Vector2d(xd, yd) - distorted).norm() < 1e-12) return m;
  return std::nullopt;
}

std::optional<Eigen::Vector3d> Lift(const UnifiedIntrinsics& intrinsics,
                                    const Eigen::Vector2d& pixel) {
  const double xi = intrinsics.xi();
  // Invert K (eq. 4).
  const double yd = (pixel.y() - intrinsics.v0()) / intrinsics.gamma_v();
  const double xd = (pixel.x() - intrinsics.u0()) / intrinsics.gamma_u() - intrinsics.alpha() * yd;
  const auto m = Undistort(intrinsics, Eigen::Vector2d(xd, yd));
  if (!m) return std::nullopt;
  // Eq. (6).
  const double r2 = m->squaredNorm();
  const double disc = 1.0 + (1.0 - xi * xi) * r2;
  if (disc < 0.0) return std::nullopt;
  const double factor = (xi + std::sqrt(disc)) / (r2 + 1.0);
  Eigen::Vector3d bearing(factor * m->x(), factor * m->y(), factor - xi);
  bearing.normalize();
  // The lifted bearing must be in the projection's domain (for xi > 1 the other root of the
  // quadratic lies beyond the horizon).
  if (!(bearing.z() + xi > 1e-12) || (xi > 1.0 && !(xi * bearing.z() + 1.0 > 1e-12))) {
    return std::nullopt;
  }
  return bearing;
}

}  // namespace omnirig
