#include "engine/estimators/triangulation.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

double AngleBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  // atan2 of |cross| and dot stays accurate for small and near-pi angles alike.
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

// Ray 1 from the origin along d1, ray 2 from c2 along d2, all in camera 1's frame. Finishes a
// triangulation from the ray parameters (lambda1, lambda2) of the closest points.
TriangulatedPoint Finish(const Eigen::Vector3d& point, const Eigen::Vector3d& c2,
                         const Eigen::Vector3d& d1, const Eigen::Vector3d& d2,
                         const TriangulationOptions& options) {
  TriangulatedPoint out;
  out.point_in_cam1 = point;
  const Eigen::Vector3d ray1 = point;
  const Eigen::Vector3d ray2 = point - c2;
  const double r1 = ray1.norm();
  const double r2 = ray2.norm();
  out.parallax_rad = AngleBetween(ray1, ray2);
  out.angular_error1_rad = AngleBetween(ray1, d1);
  out.angular_error2_rad = AngleBetween(ray2, d2);
  const double sin_p = std::sin(out.parallax_rad);
  const double cos_p = std::cos(out.parallax_rad);
  out.range_std_m =
      sin_p > 0.0 ? options.bearing_std_rad * std::sqrt(r2 * r2 + r1 * r1 * cos_p * cos_p) / sin_p
                  : std::numeric_limits<double>::infinity();
  if (out.angular_error1_rad > options.max_angular_error_rad ||
      out.angular_error2_rad > options.max_angular_error_rad) {
    // A point behind a camera reprojects near the antipode of its bearing: tell it apart from
    // rays that merely pass far apart.
    const bool behind = out.angular_error1_rad > 0.5 * M_PI || out.angular_error2_rad > 0.5 * M_PI;
    out.reason = behind ? "behind" : "reprojection";
    return out;
  }
  if (out.parallax_rad < options.min_parallax_rad) {
    out.reason = "parallax";
    return out;
  }
  out.valid = true;
  return out;
}

// Closest points of the rays lambda1 * d1 and c2 + lambda2 * d2. False when parallel.
bool ClosestRayParameters(const Eigen::Vector3d& c2, const Eigen::Vector3d& d1,
                          const Eigen::Vector3d& d2, double* lambda1, double* lambda2) {
  // Normal equations of |lambda1 d1 - lambda2 d2 - c2|^2 with unit d1, d2.
  const double b = d1.dot(d2);
  const double denom = 1.0 - b * b;
  if (!(denom > 1e-15)) return false;
  const double e = d1.dot(c2);
  const double f = d2.dot(c2);
  *lambda1 = (e - b * f) / denom;
  *lambda2 = (b * e - f) / denom;
  return true;
}

TriangulatedPoint Degenerate(const char* reason) {
  TriangulatedPoint out;
  out.reason = reason;
  return out;
}

// Both rays in camera 1's frame: ray 1 from the origin along d1, ray 2 from c2 along d2 (unit
// directions). Both triangulations start here.
struct Rays {
  Eigen::Vector3d c2;
  Eigen::Vector3d d1;
  Eigen::Vector3d d2;
};

// False when a bearing has no direction (zero or not finite).
bool SetUpRays(const Rigid3d& cam2_from_cam1, const Eigen::Vector3d& bearing1,
               const Eigen::Vector3d& bearing2, Rays* rays) {
  const double n1 = bearing1.norm();
  const double n2 = bearing2.norm();
  if (!(n1 > 0.0) || !(n2 > 0.0)) return false;
  const Eigen::Quaterniond cam1_from_cam2_rotation = cam2_from_cam1.rotation.conjugate();
  rays->c2 = -(cam1_from_cam2_rotation * cam2_from_cam1.translation);
  rays->d1 = bearing1 / n1;
  rays->d2 = cam1_from_cam2_rotation * (bearing2 / n2);
  return true;
}

}  // namespace

void TriangulationOptions::Check() const {
  OMNIRIG_CHECK_IN(min_parallax_rad, '[', 0, M_PI, ')');
  OMNIRIG_CHECK_NON_NEGATIVE(bearing_std_rad);
  OMNIRIG_CHECK_POSITIVE(max_angular_error_rad);
}

TriangulatedPoint TriangulateMidpoint(const Rigid3d& cam2_from_cam1,
                                      const Eigen::Vector3d& bearing1,
                                      const Eigen::Vector3d& bearing2,
                                      const TriangulationOptions& options) {
  Rays rays;
  if (!SetUpRays(cam2_from_cam1, bearing1, bearing2, &rays)) return Degenerate("degenerate");
  const auto& [c2, d1, d2] = rays;
  double lambda1, lambda2;
  if (!ClosestRayParameters(c2, d1, d2, &lambda1, &lambda2)) return Degenerate("parallax");
  const Eigen::Vector3d midpoint = 0.5 * (lambda1 * d1 + c2 + lambda2 * d2);
  return Finish(midpoint, c2, d1, d2, options);
}

TriangulatedPoint TriangulateOptimalAngular(const Rigid3d& cam2_from_cam1,
                                            const Eigen::Vector3d& bearing1,
                                            const Eigen::Vector3d& bearing2,
                                            const TriangulationOptions& options) {
  Rays rays;
  if (!SetUpRays(cam2_from_cam1, bearing1, bearing2, &rays)) return Degenerate("degenerate");
  const auto& [c2, d1, d2] = rays;
  const double baseline = c2.norm();
  if (!(baseline > 0.0)) return Degenerate("degenerate");

  // Every epipolar plane contains the baseline: its normal is n = cos(phi) e1 + sin(phi) e2
  // with e1, e2 spanning the baseline's orthogonal complement. sum_i (d_i . n)^2 = n^T M n is
  // minimised by the smallest eigenvector of M restricted to that plane.
  const Eigen::Vector3d axis = c2 / baseline;
  Eigen::Vector3d e1 = axis.unitOrthogonal();
  Eigen::Vector3d e2 = axis.cross(e1);
  Eigen::Matrix<double, 3, 2> basis;
  basis << e1, e2;
  const Eigen::Matrix3d m = d1 * d1.transpose() + d2 * d2.transpose();
  const Eigen::Matrix2d m2 = basis.transpose() * m * basis;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(m2);
  const Eigen::Vector3d normal = basis * eig.eigenvectors().col(0);

  Eigen::Vector3d f1 = d1 - d1.dot(normal) * normal;
  Eigen::Vector3d f2 = d2 - d2.dot(normal) * normal;
  if (!(f1.norm() > 1e-12) || !(f2.norm() > 1e-12)) return Degenerate("degenerate");
  f1.normalize();
  f2.normalize();
  double lambda1, lambda2;
  if (!ClosestRayParameters(c2, f1, f2, &lambda1, &lambda2)) return Degenerate("parallax");
  // The corrected rays are coplanar with the baseline, so they meet: take ray 1's point.
  // Reprojection is checked against the measured bearings, not the corrected ones.
  return Finish(lambda1 * f1, c2, d1, d2, options);
}

}  // namespace omnirig
