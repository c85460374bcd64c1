#include "testing/slam/surface_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace omnirig::slam {
namespace {

// Distance to the rectangle |x| <= hx, |y| <= hy of z = 0.
double ToRectangle(const Eigen::Vector3d& p, double hx, double hy) {
  const double dx = std::max(0.0, std::abs(p.x()) - hx);
  const double dy = std::max(0.0, std::abs(p.y()) - hy);
  return std::sqrt(dx * dx + dy * dy + p.z() * p.z());
}

// Distance to the surface of the box |x| <= h.x etc.
double ToBoxSurface(const Eigen::Vector3d& p, const Eigen::Vector3d& h) {
  const Eigen::Vector3d q = p.cwiseAbs() - h;
  if ((q.array() <= 0).all()) return -q.maxCoeff();  // inside: nearest face
  return q.cwiseMax(0.0).norm();
}

double ToCylinderSurface(const Eigen::Vector3d& p, double radius, double height) {
  const double r = std::hypot(p.x(), p.y());
  const double dr = r - radius;                             // > 0 outside the side
  const double dz = std::max(-p.z(), p.z() - height);       // > 0 beyond a cap
  if (dr <= 0 && dz <= 0) return std::min(-dr, -dz);
  return std::hypot(std::max(dr, 0.0), std::max(dz, 0.0));
}

}  // namespace

double DistanceToSceneSurface(const synth::Scene& scene, const Eigen::Vector3d& point_in_world) {
  double best = std::numeric_limits<double>::infinity();
  for (const synth::PrimitiveInfo& primitive : scene.primitives()) {
    const Eigen::Vector3d p = primitive.world_from_local.Inverse() * point_in_world;
    const Eigen::Vector3d& size = primitive.size_m;
    double d = best;
    switch (primitive.kind) {
      case synth::PrimitiveInfo::Kind::kPlane:
        d = ToRectangle(p, size.x() / 2, size.y() / 2);
        break;
      case synth::PrimitiveInfo::Kind::kBox:
        d = ToBoxSurface(p, size / 2);
        break;
      case synth::PrimitiveInfo::Kind::kCylinder:
        d = ToCylinderSurface(p, size.x(), size.z());
        break;
      case synth::PrimitiveInfo::Kind::kCheckerboard: {
        // The board rectangle spans [-square - margin, cols * square + margin] in x, etc.
        const synth::CheckerboardSpec& board = *primitive.board;
        const double x0 = -board.square_size_m - board.margin_m;
        const double y0 = x0;
        const Eigen::Vector3d centred(p.x() - (x0 + board.width_m() / 2),
                                      p.y() - (y0 + board.height_m() / 2), p.z());
        d = ToRectangle(centred, board.width_m() / 2, board.height_m() / 2);
        break;
      }
    }
    best = std::min(best, d);
  }
  return best;
}

}  // namespace omnirig::slam
