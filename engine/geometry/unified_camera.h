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
//
// Derivatives (basalt's camera headers are the model): Project() optionally returns
// d pixel / d point_in_cam (2x3) and d pixel / d params (2x11), Lift() d bearing / d pixel
// (3x2), in closed form, valid wherever the function itself is. The projection is invariant to
// the point's scale, so d pixel / d point_in_cam * point_in_cam = 0; the lifted bearing is a unit
// vector, so bearing^T * d bearing / d pixel = 0. Everything is templated on the scalar (double
// and float are tested against central differences; ProjectToPixel also takes Ceres Jets).

#include <array>
#include <cmath>
#include <optional>
#include <algorithm>

#include <Eigen/Core>
#include <Eigen/LU>

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

template <typename T>
using Vector2 = Eigen::Matrix<T, 2, 1>;
template <typename T>
using Vector3 = Eigen::Matrix<T, 3, 1>;
// An Eigen matrix whose scalar is not deduced from the argument (so that nullptr is accepted for
// an optional Jacobian).
template <typename T, int Rows, int Cols, int Options = Eigen::ColMajor>
using JacobianOf = Eigen::Matrix<typename Eigen::NumTraits<T>::Real, Rows, Cols, Options>;
// d pixel / d params is row-major, as Ceres lays out a parameter block's Jacobian.
template <typename T>
using IntrinsicsJacobianOf = JacobianOf<T, 2, UnifiedIntrinsics::kNumParams, Eigen::RowMajor>;

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

// d D(m) / d m of eq. (3) at m = (x, y): the one place it is written (the projection's
// Jacobians and the Newton iteration of Undistort both use it).
template <typename T>
inline Eigen::Matrix<T, 2, 2> DistortionJacobian(const T* params, const T& x, const T& y) {
  using I = UnifiedIntrinsics;
  const T rho2 = x * x + y * y;
  const T radial = T(1) + params[I::kK1] * rho2 + params[I::kK2] * rho2 * rho2 +
                   params[I::kK5] * rho2 * rho2 * rho2;
  const T dr = params[I::kK1] + T(2) * params[I::kK2] * rho2 + T(3) * params[I::kK5] * rho2 * rho2;
  const T k3 = params[I::kK3], k4 = params[I::kK4];
  Eigen::Matrix<T, 2, 2> jacobian;
  jacobian(0, 0) = radial + T(2) * x * x * dr + T(2) * k3 * y + T(6) * k4 * x;
  jacobian(0, 1) = T(2) * x * y * dr + T(2) * k3 * x + T(2) * k4 * y;
  jacobian(1, 0) = T(2) * x * y * dr + T(2) * k4 * y + T(2) * k3 * x;
  jacobian(1, 1) = radial + T(2) * y * y * dr + T(2) * k4 * x + T(6) * k3 * y;
  return jacobian;
}

// Eq. (2): the point's norm and its image m = (x, y) on the normalised plane. False outside
// the valid domain documented above. Templated for Ceres Jets.
template <typename T>
inline bool NormalisedPlanePoint(const T* params, const T* point_in_cam, T* norm, T* x, T* y) {
  using std::sqrt;
  const T norm2 = point_in_cam[0] * point_in_cam[0] + point_in_cam[1] * point_in_cam[1] +
                  point_in_cam[2] * point_in_cam[2];
  if (!(norm2 > T(1e-300))) return false;
  *norm = sqrt(norm2);
  const T zs = point_in_cam[2] / *norm;
  const T& xi = params[UnifiedIntrinsics::kXi];
  // zs > -min(xi, 1/xi)  <=>  zs + xi > 0 and (xi <= 1 or xi * zs + 1 > 0).
  if (!(zs + xi > T(1e-12))) return false;
  if (xi > T(1) && !(xi * zs + T(1) > T(1e-12))) return false;
  const T denom = zs + xi;
  *x = point_in_cam[0] / *norm / denom;
  *y = point_in_cam[1] / *norm / denom;
  return true;
}

// Eqs. (2)-(4): projects a point in the mirror (camera) frame to a pixel. Returns false, leaving
// `pixel` untouched, outside the valid domain documented above. Templated for Ceres Jets.
template <typename T>
inline bool ProjectToPixel(const T* params, const T* point_in_cam, T* pixel) {
  using I = UnifiedIntrinsics;
  T norm, x, y, xd, yd;
  if (!NormalisedPlanePoint(params, point_in_cam, &norm, &x, &y)) return false;
  Distort(params, x, y, &xd, &yd);
  pixel[0] = params[I::kGammaU] * (xd + params[I::kAlpha] * yd) + params[I::kU0];
  pixel[1] = params[I::kGammaV] * yd + params[I::kV0];
  return true;
}

// Eqs. (2)-(4) with their Jacobians: `pixel` of `point_in_cam`, and when not null
// d pixel / d point_in_cam and d pixel / d params. False (outputs untouched) outside the valid
// domain.
template <typename T>
inline bool Project(const T* params, const Vector3<T>& point_in_cam, Vector2<T>* pixel,
                    JacobianOf<T, 2, 3>* d_pixel_d_point = nullptr,
                    IntrinsicsJacobianOf<T>* d_pixel_d_params = nullptr) {
  using I = UnifiedIntrinsics;
  if (d_pixel_d_point == nullptr && d_pixel_d_params == nullptr) {
    return ProjectToPixel(params, point_in_cam.data(), pixel->data());
  }
  // The chain point -> unit sphere s -> normalised plane m -> distorted m_d -> pixel, each
  // step's value computed once (as ProjectToPixel does).
  T norm, x, y, xd, yd;
  if (!NormalisedPlanePoint(params, point_in_cam.data(), &norm, &x, &y)) return false;
  Distort(params, x, y, &xd, &yd);
  (*pixel)[0] = params[I::kGammaU] * (xd + params[I::kAlpha] * yd) + params[I::kU0];
  (*pixel)[1] = params[I::kGammaV] * yd + params[I::kV0];
  const Vector3<T> s = point_in_cam / norm;
  const T denom = s.z() + params[I::kXi];
  Eigen::Matrix<T, 2, 2> dp_dmd;
  dp_dmd << params[I::kGammaU], params[I::kGammaU] * params[I::kAlpha], T(0), params[I::kGammaV];
  const Eigen::Matrix<T, 2, 2> dp_dm = dp_dmd * DistortionJacobian(params, x, y);
  if (d_pixel_d_point != nullptr) {
    // d s / d X = (I - s s^T) / |X|;  d m / d s from m = (s_x, s_y) / (s_z + xi).
    const Eigen::Matrix<T, 3, 3> ds_dX =
        (Eigen::Matrix<T, 3, 3>::Identity() - s * s.transpose()) / norm;
    Eigen::Matrix<T, 2, 3> dm_ds;
    dm_ds << T(1) / denom, T(0), -x / denom, T(0), T(1) / denom, -y / denom;
    *d_pixel_d_point = dp_dm * dm_ds * ds_dX;
  }
  if (d_pixel_d_params != nullptr) {
    IntrinsicsJacobianOf<T>& J = *d_pixel_d_params;
    const T rho2 = x * x + y * y, rho4 = rho2 * rho2;
    J.setZero();
    J.col(I::kXi) = dp_dm * Vector2<T>(-x / denom, -y / denom);
    J(0, I::kGammaU) = xd + params[I::kAlpha] * yd;
    J(1, I::kGammaV) = yd;
    J(0, I::kU0) = T(1);
    J(1, I::kV0) = T(1);
    J(0, I::kAlpha) = params[I::kGammaU] * yd;
    J.col(I::kK1) = dp_dmd * Vector2<T>(x * rho2, y * rho2);
    J.col(I::kK2) = dp_dmd * Vector2<T>(x * rho4, y * rho4);
    J.col(I::kK3) = dp_dmd * Vector2<T>(T(2) * x * y, rho2 + T(2) * y * y);
    J.col(I::kK4) = dp_dmd * Vector2<T>(rho2 + T(2) * x * x, T(2) * x * y);
    J.col(I::kK5) = dp_dmd * Vector2<T>(x * rho4 * rho2, y * rho4 * rho2);
  }
  return true;
}

// Convergence threshold of the Newton iteration on the normalised plane: 1e-14 in double, a few
// ulps in float.
template <typename T>
inline T UndistortTolerance() {
  return std::max(T(1e-14), T(8) * Eigen::NumTraits<T>::epsilon());
}

// Inverse of the distortion D (eq. 3) by Newton's method: false when it does not converge to
// 1e-12 (a few ulps in float) on the normalised plane.
template <typename T>
inline bool Undistort(const T* params, const Vector2<T>& distorted, Vector2<T>* undistorted) {
  const T accept = std::max(T(1e-12), T(64) * Eigen::NumTraits<T>::epsilon());
  Vector2<T> m = distorted;
  for (int iter = 0; iter < 50; ++iter) {
    Vector2<T> residual;
    Distort(params, m.x(), m.y(), &residual.x(), &residual.y());
    residual -= distorted;
    if (!residual.allFinite()) return false;
    if (residual.norm() < UndistortTolerance<T>()) {
      *undistorted = m;
      return true;
    }
    const Eigen::Matrix<T, 2, 2> jacobian = DistortionJacobian(params, m.x(), m.y());
    if (!(std::abs(jacobian.determinant()) > T(1e-12))) return false;
    m -= jacobian.inverse() * residual;
  }
  Vector2<T> back;
  Distort(params, m.x(), m.y(), &back.x(), &back.y());
  if (!((back - distorted).norm() < accept)) return false;
  *undistorted = m;
  return true;
}

// Eq. (6) after inverting K and D: the unit bearing (on the sphere, in the mirror frame) of a
// pixel, and when not null d bearing / d pixel. False outside the valid domain documented above.
template <typename T>
inline bool Lift(const T* params, const Vector2<T>& pixel, Vector3<T>* bearing,
                 JacobianOf<T, 3, 2>* d_bearing_d_pixel = nullptr) {
  using I = UnifiedIntrinsics;
  const T xi = params[I::kXi];
  // Invert K (eq. 4).
  const T yd = (pixel.y() - params[I::kV0]) / params[I::kGammaV];
  const T xd = (pixel.x() - params[I::kU0]) / params[I::kGammaU] - params[I::kAlpha] * yd;
  Vector2<T> m;
  if (!Undistort(params, Vector2<T>(xd, yd), &m)) return false;
  // Eq. (6).
  const T r2 = m.squaredNorm();
  const T disc = T(1) + (T(1) - xi * xi) * r2;
  if (disc < T(0)) return false;
  const T factor = (xi + std::sqrt(disc)) / (r2 + T(1));
  Vector3<T> lifted(factor * m.x(), factor * m.y(), factor - xi);
  lifted.normalize();
  // The lifted bearing must be in the projection's domain (for xi > 1 the other root of the
  // quadratic lies beyond the horizon).
  if (!(lifted.z() + xi > T(1e-12)) || (xi > T(1) && !(xi * lifted.z() + T(1) > T(1e-12)))) {
    return false;
  }
  if (d_bearing_d_pixel != nullptr) {
    // Lifting inverts the projection on the unit sphere: d pixel / d bearing * J = I and
    // bearing^T J = 0 determine J.
    Vector2<T> unused;
    Eigen::Matrix<T, 3, 3> constraints;
    Eigen::Matrix<T, 2, 3> d_pixel_d_point;
    if (!Project(params, lifted, &unused, &d_pixel_d_point)) return false;
    constraints << d_pixel_d_point, lifted.transpose();
    *d_bearing_d_pixel = constraints.inverse().template leftCols<2>();
  }
  *bearing = lifted;
  return true;
}

// Convenience wrappers in double.
std::optional<Eigen::Vector2d> Project(const UnifiedIntrinsics& intrinsics,
                                       const Eigen::Vector3d& point_in_cam);

std::optional<Eigen::Vector2d> Undistort(const UnifiedIntrinsics& intrinsics,
                                         const Eigen::Vector2d& distorted);

std::optional<Eigen::Vector3d> Lift(const UnifiedIntrinsics& intrinsics,
                                    const Eigen::Vector2d& pixel);

}  // namespace omnirig
