#include "testing/slam/surface_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

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

constexpr double kMinT = 1e-6;
constexpr double kInf = std::numeric_limits<double>::infinity();

// First t > kMinT where the ray o + t d meets the rectangle |x| <= hx, |y| <= hy of z = 0.
double RayRectangle(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double hx, double hy) {
  if (d.z() == 0.0) return kInf;
  const double t = -o.z() / d.z();
  if (!(t > kMinT)) return kInf;
  const Eigen::Vector3d p = o + t * d;
  return std::abs(p.x()) <= hx && std::abs(p.y()) <= hy ? t : kInf;
}

// First t > kMinT where the ray meets the surface of the box |x| <= h.x etc. (from inside or
// outside): the slab interval's entry, or its exit when the origin is inside.
double RayBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& h) {
  double enter = -kInf, leave = kInf;
  for (int i = 0; i < 3; ++i) {
    if (d[i] == 0.0) {
      if (std::abs(o[i]) > h[i]) return kInf;
      continue;
    }
    double t0 = (-h[i] - o[i]) / d[i], t1 = (h[i] - o[i]) / d[i];
    if (t0 > t1) std::swap(t0, t1);
    enter = std::max(enter, t0);
    leave = std::min(leave, t1);
  }
  if (enter > leave) return kInf;
  if (enter > kMinT) return enter;
  return leave > kMinT ? leave : kInf;
}

// First t > kMinT where the ray meets the cylinder x^2 + y^2 = radius^2, 0 <= z <= height, or
// its caps.
double RayCylinder(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double radius,
                   double height) {
  double best = kInf;
  const double a = d.x() * d.x() + d.y() * d.y();
  if (a > 0.0) {
    const double b = o.x() * d.x() + o.y() * d.y();
    const double c = o.x() * o.x() + o.y() * o.y() - radius * radius;
    const double disc = b * b - a * c;
    if (disc >= 0.0) {
      for (const double t : {(-b - std::sqrt(disc)) / a, (-b + std::sqrt(disc)) / a}) {
        const double z = o.z() + t * d.z();
        if (t > kMinT && z >= 0.0 && z <= height) best = std::min(best, t);
      }
    }
  }
  if (d.z() != 0.0) {
    for (const double cap : {0.0, height}) {
      const double t = (cap - o.z()) / d.z();
      const Eigen::Vector3d p = o + t * d;
      if (t > kMinT && p.x() * p.x() + p.y() * p.y() <= radius * radius) best = std::min(best, t);
    }
  }
  return best;
}

}  // namespace

double RangeToSceneSurface(const synth::Scene& scene, const Eigen::Vector3d& origin_in_world,
                           const Eigen::Vector3d& unit_direction_in_world) {
  double best = kInf;
  for (const synth::PrimitiveInfo& primitive : scene.primitives()) {
    const Rigid3d local_from_world = primitive.world_from_local.Inverse();
    const Eigen::Vector3d o = local_from_world * origin_in_world;
    const Eigen::Vector3d d = local_from_world.rotation * unit_direction_in_world;
    const Eigen::Vector3d& size = primitive.size_m;
    switch (primitive.kind) {
      case synth::PrimitiveInfo::Kind::kPlane:
        best = std::min(best, RayRectangle(o, d, size.x() / 2, size.y() / 2));
        break;
      case synth::PrimitiveInfo::Kind::kBox:
        best = std::min(best, RayBox(o, d, size / 2));
        break;
      case synth::PrimitiveInfo::Kind::kCylinder:
        best = std::min(best, RayCylinder(o, d, size.x(), size.z()));
        break;
      case synth::PrimitiveInfo::Kind::kCheckerboard: {
        const synth::CheckerboardSpec& board = *primitive.board;
        const double x0 = -board.square_size_m - board.margin_m;
        const Eigen::Vector3d centre(x0 + board.width_m() / 2, x0 + board.height_m() / 2, 0.0);
        best =
            std::min(best, RayRectangle(o - centre, d, board.width_m() / 2, board.height_m() / 2));
        break;
      }
    }
  }
  return best;
}

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
