#pragma once
// The one pose type of omnirig: a rotation (unit quaternion) and a translation.
//
// Naming: a `Rigid3d a_from_b` maps coordinates in frame b into frame a:
//   point_in_a = a_from_b * point_in_b.
// Composition reads left to right with matching names:
//   cam_from_world = cam_from_rig * rig_from_world.
//
// Parameter blocks: Ceres problems hold a pose as one block of 7 doubles in Eigen's storage
// order [qx, qy, qz, qw, tx, ty, tz] with ceres::EigenQuaternionManifold on the first four
// (see NewPoseManifold() in engine/geometry/ceres_problem.h). The paper and JSON use (w, x, y, z);
// the conversion happens only in ToWxyz()/FromWxyz() below.

#include <array>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace omnirig {

struct Rigid3d {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Rigid3d() = default;
  Rigid3d(const Eigen::Quaterniond& r, const Eigen::Vector3d& t)
      : rotation(r.normalized()), translation(t) {}

  Eigen::Vector3d operator*(const Eigen::Vector3d& point) const {
    return rotation * point + translation;
  }
  Rigid3d operator*(const Rigid3d& other) const {
    return Rigid3d(rotation * other.rotation, rotation * other.translation + translation);
  }
  Rigid3d Inverse() const {
    const Eigen::Quaterniond inv = rotation.conjugate();
    return Rigid3d(inv, -(inv * translation));
  }
  Eigen::Matrix3d RotationMatrix() const { return rotation.toRotationMatrix(); }
  Eigen::Matrix<double, 3, 4> ToMatrix3x4() const {
    Eigen::Matrix<double, 3, 4> m;
    m << RotationMatrix(), translation;
    return m;
  }

  // Ceres parameter block, Eigen order [qx, qy, qz, qw, tx, ty, tz].
  std::array<double, 7> ToParams() const;
  static Rigid3d FromParams(const double* params);

  // The one place where quaternion component order changes: (w, x, y, z) as in the paper's
  // eq. (1) and every JSON document.
  std::array<double, 4> ToWxyz() const;
  static Eigen::Quaterniond FromWxyz(const std::array<double, 4>& wxyz);
};

// Angle of the rotation a^-1 * b, in radians.
double RotationDistanceRad(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);

// The cross-product matrix: Skew(a) * b == a.cross(b).
inline Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

}  // namespace omnirig
