#pragma once
// Mei's unified projection model for central catadioptric cameras, as in the omnirig paper
// ("A 3D omnidirectional sensor for mobile robot applications", section 3.1, eqs. (1)-(6)).
//
// Parameter vector (kNumParams = 11 doubles), in this order:
//   [xi, gamma_u, gamma_v, u0, v0, alpha, k1, k2, k3, k4, k5]
//   xi              distance of the second projection centre from the sphere's centre (eq. 2)
//   gamma_u/gamma_v generalised focal lengths in pixels (eq. 4)
//   u0, v0          principal point in pixels
//   alpha           skew; eq. (4) puts gamma_u * alpha in K(0, 1)
//   k1, k2, k5      radial distortion of rho^2, rho^4, rho^6 (eq. 3)
//   k3, k4          tangential distortion (eq. 3). OpenCV omnidir's D = (k1, k2, p1, p2) maps
//                   onto (k1, k2, k3, k4) with k5 = 0.
//
// Pixel convention: the centre of the top-left pixel is (0, 0).
//
// Projection (point_in_cam -> pixel), eq. (2)-(4):
//   X_s = X / |X|;  m = (X_s.x, X_s.y) / (X_s.z + xi);  m_d = D(m);  p = K m_d.
//   Valid domain: |X| > 0 and X_s.z > -min(xi, 1/xi) (for xi <= 1 the denominator stays
//   positive; for xi > 1 the sphere-to-plane map folds over beyond X_s.z = -1/xi). xi >= 0.
//   The distortion itself is assumed monotone over the image; lifting verifies it.
// Lifting (pixel -> unit bearing), eq. (6) after inverting K and D:
//   m_d = K^-1 p; m = D^-1(m_d) by Newton iterations; then eq. (6).
//   Valid domain: the Newton iteration converges (|D(m) - m_d| < 1e-12) and
//   1 + (1 - xi^2) |m|^2 >= 0 (for xi > 1 the image of the horizon bounds |m|), and the lifted
//   bearing lies in the projection's valid domain so that project(lift(p)) == p.

#include <array>
#include <cmath>
#include <optional>

#include <Eigen/Core>

#include "engine/util/check.h"

namespace omnirig {

struct UnifiedIntrinsics {
  static constexpr int kNumParams = 11;
  enum Index { kXi = 0, kGammaU, kGammaV, kU0, kV0, kAlpha, kK1, kK2, kK3, kK4, kK5 };
  static constexpr const char* kNames[kNumParams] = {
      "xi", "gamma_u", "gamma_v", "u0", "v0", "alpha", "k1", "k2", "k3", "k4", "k5"};

  std::array<double, kNumParams> params{1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0, 0, 0, 0, 0};

  double& xi() { return params[kXi]; }
  double xi() const { return params[kXi]; }
  double& gamma_u() { return params[kGammaU]; }
  double gamma_u() const { return params[kGammaU]; }
  double& gamma_v() { return params[kGammaV]; }
  double gamma_v() const { return params[kGammaV]; }
  double& u0() { return params[kU0]; }
  double u0() const { return params[kU0]; }
  double& v0() { return params[kV0]; }
  double v0() const { return params[kV0]; }
  double& alpha() { return params[kAlpha]; }
  double alpha() const { return params[kAlpha]; }
  double& k(int i) { return params[kK1 + i - 1]; }  // k(1) .. k(5), the paper's names
  double k(int i) const { return params[kK1 + i - 1]; }

  // Throws InvalidArgument when a parameter is out of its physical range (xi < 0, a
  // non-positive focal length, a non-finite value).
  void Check() const;
};

// Eq. (3): the distortion D applied to a point m on the normalised plane.
template <typename T>
inline void Distort(const T* params, const T& x, const T& y, T* xd, T* yd) {
  using I = UnifiedIntrinsics;
  const T rho2 = x * x + y * y;
  const T radial =
      T(1) + params[I::kK1] * rho2 + params[I::kK2] * rho2 * rho2 +
      params[I::kK5] * rho2 * rho2 * rho2;
  *xd = x * radial + T(2) * params[I::kK3] * x * y + params[I::kK4] * (rho2 + T(2) * x * x);
  *yd = y * radial + T(2) * params[I::kK4] * x * y + params[I::kK3] * (rho2 + T(2) * y * y);
}

// Eqs. (2)-(4): projects a point in the mirror (camera) frame to a pixel. Returns false, leaving
// `pixel` untouched, outside the valid domain documented above. Templated for Ceres Jets.
template <typename T>
inline bool ProjectToPixel(const T* params, const T* point_in_cam, T* pixel) {
  using I = UnifiedIntrinsics;
  using std::sqrt;
  const T norm2 = point_in_cam[0] * point_in_cam[0] + point_in_cam[1] * point_in_cam[1] +
                  point_in_cam[2] * point_in_cam[2];
  if (!(norm2 > T(1e-300))) return false;
  const T norm = sqrt(norm2);
  const T zs = point_in_cam[2] / norm;
  const T& xi = params[I::kXi];
  // zs > -min(xi, 1/xi)  <=>  zs + xi > 0 and (xi <= 1 or xi * zs + 1 > 0).
  if (!(zs + xi > T(1e-12))) return false;
  if (xi > T(1) && !(xi * zs + T(1) > T(1e-12))) return false;
  const T denom = zs + xi;
  const T x = point_in_cam[0] / norm / denom;
  const T y = point_in_cam[1] / norm / denom;
  T xd, yd;
  Distort(params, x, y, &xd, &yd);
  pixel[0] = params[I::kGammaU] * (xd + params[I::kAlpha] * yd) + params[I::kU0];
  pixel[1] = params[I::kGammaV] * yd + params[I::kV0];
  return true;
}

// Convenience wrappers in double.
std::optional<Eigen::Vector2d> Project(const UnifiedIntrinsics& intrinsics,
                                       const Eigen::Vector3d& point_in_cam);

// Projection with its Jacobian d(pixel)/d(point_in_cam), computed analytically (tested
// against Jets and central differences).
std::optional<Eigen::Vector2d> ProjectWithJacobian(const UnifiedIntrinsics& intrinsics,
                                                   const Eigen::Vector3d& point_in_cam,
                                                   Eigen::Matrix<double, 2, 3>* d_pixel_d_point);

// Inverse of the distortion D (eq. 3) by Newton's method. Returns nullopt when it does not
// converge to 1e-12 on the normalised plane.
std::optional<Eigen::Vector2d> Undistort(const UnifiedIntrinsics& intrinsics,
                                         const Eigen::Vector2d& distorted);

// Eq. (6) after inverting K and D: the unit bearing (on the sphere, in the mirror frame) of a
// pixel. nullopt outside the valid domain documented above.
std::optional<Eigen::Vector3d> Lift(const UnifiedIntrinsics& intrinsics,
                                    const Eigen::Vector2d& pixel);

}  // namespace omnirig
