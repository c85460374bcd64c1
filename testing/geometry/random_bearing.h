#pragma once
// Seeded random bearings for tests and benches (the same draws on every run).

#include <random>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace omnirig {

// A direction uniform on the unit sphere.
inline Eigen::Vector3d RandomUnitVector(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized();
}

// Perturbs a unit bearing by an angle drawn from N(0, sigma_rad) about a random perpendicular
// axis (sigma_rad 0: unchanged).
inline Eigen::Vector3d PerturbBearing(const Eigen::Vector3d& bearing, double sigma_rad,
                                      std::mt19937_64& rng) {
  if (sigma_rad <= 0.0) return bearing;
  std::normal_distribution<double> n(0.0, sigma_rad);
  const Eigen::Vector3d axis = bearing.cross(RandomUnitVector(rng)).normalized();
  return Eigen::AngleAxisd(n(rng), axis) * bearing;
}

}  // namespace omnirig
