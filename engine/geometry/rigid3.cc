#include "engine/geometry/rigid3.h"

#include <algorithm>
#include <cmath>

namespace omnirig {

std::array<double, 7> Rigid3d::ToParams() const {
  const Eigen::Quaterniond q = rotation.normalized();
  return {q.x(), q.y(), q.z(), q.w(), translation.x(), translation.y(), translation.z()};
}

Rigid3d Rigid3d::FromParams(const double* params) {
  const Eigen::Quaterniond q(params[3], params[0], params[1], params[2]);
  return Rigid3d(q, Eigen::Vector3d(params[4], params[5], params[6]));
}

std::array<double, 4> Rigid3d::ToWxyz() const {
  const Eigen::Quaterniond q = rotation.normalized();
  return {q.w(), q.x(), q.y(), q.z()};
}

Eigen::Quaterniond Rigid3d::FromWxyz(const std::array<double, 4>& wxyz) {
  return Eigen::Quaterniond(wxyz[0], wxyz[1], wxyz[2], wxyz[3]).normalized();
}

double RotationDistanceRad(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  const Eigen::Quaterniond d = a.conjugate() * b;
  const double w = std::min(1.0, std::abs(d.normalized().w()));
  return 2.0 * std::acos(w);
}

}  // namespace omnirig
