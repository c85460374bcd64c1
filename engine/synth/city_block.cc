#include "engine/synth/city_block.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "engine/util/option_check.h"

namespace omnirig::synth {
namespace {

constexpr double kBuildingDepthM = 6.0;
constexpr double kGroundTileM = 8.0;  // ground tiles of about this side keep texels near 1 cm

Rigid3d Place(const Eigen::Vector2d& xy, double z, double yaw_rad) {
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ())),
                 Eigen::Vector3d(xy.x(), xy.y(), z));
}

// A row of buildings whose façades lie on the segment from `start` to `end`, each extending
// `depth` metres towards `back` (a unit vector normal to the segment), of varied widths, heights
// and colours. `salt` separates the rows' texture seeds.
void AddBuildingRow(const Eigen::Vector2d& start, const Eigen::Vector2d& end,
                    const Eigen::Vector2d& back, double depth, uint64_t seed, uint64_t salt,
                    const std::string& name, Scene* scene) {
  const double widths[] = {7.0, 5.0, 8.5, 6.0, 4.5, 7.5, 5.5};
  const double length = (end - start).norm();
  if (length < 0.5 || depth < 0.5) return;
  const Eigen::Vector2d along = (end - start) / length;
  const double yaw = std::atan2(along.y(), along.x());
  double x = 0.0;
  for (int b = 0; x < length - 1e-9; ++b) {
    double width = widths[(b + salt) % 7];
    if (length - x < width + 2.0) width = length - x;  // no sliver at the row's end
    const double height = 5.0 + 1.0 * ((b * 3 + salt) % 5);
    const Eigen::Vector3d rgb(0.65 + 0.1 * ((b + salt) % 4), 0.6 + 0.1 * ((b + 2 * salt) % 3),
                              0.5 + 0.12 * ((b + salt) % 3));
    const Eigen::Vector2d centre = start + (x + 0.5 * width) * along + 0.5 * depth * back;
    scene->AddBox(Place(centre, 0.5 * height, yaw), Eigen::Vector3d(width, depth, height),
                  RichTexture(seed, 1000 * salt + b, rgb, 30.0, 0.012),
                  name + "_" + std::to_string(b));
    x += width;
  }
}

void AddBuildings(const CityBlockLoop& loop, uint64_t seed, Scene* scene) {
  const Eigen::Vector2d core = loop.core_half_size();
  const double a = core.x(), b = core.y();
  // The block: south and north rows span the core's length; east and west rows fill between.
  const double depth = std::min(kBuildingDepthM, b);
  AddBuildingRow({-a, -b}, {a, -b}, {0, 1}, depth, seed, 1, "block_south", scene);
  AddBuildingRow({a, b}, {-a, b}, {0, -1}, depth, seed, 2, "block_north", scene);
  AddBuildingRow({a, -b + depth}, {a, b - depth}, {-1, 0}, std::min(kBuildingDepthM, a), seed, 3,
                 "block_east", scene);
  AddBuildingRow({-a, b - depth}, {-a, -b + depth}, {1, 0}, std::min(kBuildingDepthM, a), seed,
                 4, "block_west", scene);
  // Across the street: south and north rows run past the corners to close them.
  const double street = CityBlockLoop::kPathOffsetM + CityBlockLoop::kFarFacadeM;
  const double fa = a + street, fb = b + street, d = kBuildingDepthM;
  AddBuildingRow({fa + d, -fb}, {-fa - d, -fb}, {0, -1}, d, seed, 5, "far_south", scene);
  AddBuildingRow({-fa - d, fb}, {fa + d, fb}, {0, 1}, d, seed, 6, "far_north", scene);
  AddBuildingRow({fa, fb}, {fa, -fb}, {1, 0}, d, seed, 7, "far_east", scene);
  AddBuildingRow({-fa, -fb}, {-fa, fb}, {-1, 0}, d, seed, 8, "far_west", scene);
}

// The street's surface as tiles (one texture per tile keeps texels fine), without the tiles
// hidden under the block.
void AddGround(const CityBlockLoop& loop, uint64_t seed, Scene* scene) {
  const Eigen::Vector2d core = loop.core_half_size();
  const double street = CityBlockLoop::kPathOffsetM + CityBlockLoop::kFarFacadeM;
  const Eigen::Vector2d half = core + Eigen::Vector2d::Constant(street);
  const int nx = static_cast<int>(std::ceil(2.0 * half.x() / kGroundTileM));
  const int ny = static_cast<int>(std::ceil(2.0 * half.y() / kGroundTileM));
  const double sx = 2.0 * half.x() / nx, sy = 2.0 * half.y() / ny;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const double x0 = -half.x() + i * sx, y0 = -half.y() + j * sy;
      const bool under_block =
          x0 >= -core.x() && x0 + sx <= core.x() && y0 >= -core.y() && y0 + sy <= core.y();
      if (under_block) continue;
      const Eigen::Vector3d rgb(0.52 + 0.04 * ((i + j) % 3), 0.52 + 0.03 * (i % 2), 0.55);
      scene->AddPlane(Place({x0 + 0.5 * sx, y0 + 0.5 * sy}, 0.0, 0.0), sx, sy,
                      RichTexture(seed, 20000 + j * nx + i, rgb, 30.0, 0.01),
                      "ground_" + std::to_string(i) + "_" + std::to_string(j));
    }
  }
}

// Poles on both sides of the street, alternating, and cars parked on its far side along the
// straight stretches: near structure for stereo, at distinct places around the loop.
void AddStreetFurniture(const CityBlockLoop& loop, uint64_t seed, Scene* scene) {
  const double pole_spacing = 9.0;
  const int num_poles = static_cast<int>(loop.length_m() / pole_spacing);
  for (int i = 0; i < num_poles; ++i) {
    Eigen::Vector2d point, outward;
    loop.At((i + 0.3) * loop.length_m() / num_poles, &point, &outward);
    const double side = i % 2 == 0 ? -3.0 : 4.6;  // by the block or by the far façades
    scene->AddCylinder(Place(point + side * outward, 0.0, 0.0), 0.1 + 0.03 * (i % 3),
                       3.5 + 0.5 * (i % 3),
                       RichTexture(seed, 30000 + i, Eigen::Vector3d(0.6, 0.6, 0.62), 200.0),
                       "pole_" + std::to_string(i));
  }
  const double car_spacing = 17.0, car_length = 4.0;
  const int num_cars = static_cast<int>(loop.length_m() / car_spacing);
  for (int i = 0; i < num_cars; ++i) {
    const double u = (i + 0.6) * loop.length_m() / num_cars;
    Eigen::Vector2d point, outward, before, after, unused;
    loop.At(u, &point, &outward);
    loop.At(u - car_length, &unused, &before);
    loop.At(u + car_length, &unused, &after);
    if ((before - after).norm() > 1e-9) continue;  // not on a straight stretch
    const double yaw = std::atan2(outward.x(), -outward.y());  // along the path
    const Eigen::Vector3d rgb(0.3 + 0.15 * (i % 4), 0.35 + 0.1 * (i % 3), 0.85 - 0.15 * (i % 4));
    scene->AddBox(Place(point + 3.5 * outward, 0.7, yaw), Eigen::Vector3d(car_length, 1.8, 1.4),
                  RichTexture(seed, 40000 + i, rgb, 80.0), "car_" + std::to_string(i));
  }
}

}  // namespace

CityBlockLoop::CityBlockLoop(double length_m) : length_m_(length_m) {
  OMNIRIG_CHECK_IN(length_m, '[', kMinLengthM, kMaxLengthM, ']');
  // length = 4 a + 4 b + 2 pi r with a = 2 b (half extents of the core).
  const double b = (length_m - 2.0 * M_PI * kPathOffsetM) / 12.0;
  core_half_ = Eigen::Vector2d(2.0 * b, b);
}

void CityBlockLoop::At(double u, Eigen::Vector2d* point, Eigen::Vector2d* outward) const {
  const double a = core_half_.x(), b = core_half_.y(), r = kPathOffsetM;
  const double quarter = 0.5 * M_PI * r;
  double v = std::fmod(u, length_m_);
  if (v < 0.0) v += length_m_;
  // Straight sides (start on the core's edge, direction) and corners (core corner, start angle),
  // in driving order; the first straight is the east half of the south side.
  const struct {
    double length;
    Eigen::Vector2d origin, direction;  // a straight: q = origin + v direction
    double angle;                       // a corner: q = origin, normal at angle + v / r
    bool corner;
  } pieces[] = {
      {a, {0, -b}, {1, 0}, 0, false},           {quarter, {a, -b}, {0, 0}, -0.5 * M_PI, true},
      {2 * b, {a, -b}, {0, 1}, 0, false},       {quarter, {a, b}, {0, 0}, 0.0, true},
      {2 * a, {a, b}, {-1, 0}, 0, false},       {quarter, {-a, b}, {0, 0}, 0.5 * M_PI, true},
      {2 * b, {-a, b}, {0, -1}, 0, false},      {quarter, {-a, -b}, {0, 0}, M_PI, true},
      {a + 1.0, {-a, -b}, {1, 0}, 0, false},  // + 1: rounding at the wrap
  };
  for (const auto& piece : pieces) {
    if (v > piece.length) {
      v -= piece.length;
      continue;
    }
    if (piece.corner) {
      const double angle = piece.angle + v / r;
      *outward = Eigen::Vector2d(std::cos(angle), std::sin(angle));
      *point = piece.origin + r * *outward;
    } else {
      *outward = Eigen::Vector2d(piece.direction.y(), -piece.direction.x());
      *point = piece.origin + v * piece.direction + r * *outward;
    }
    return;
  }
}

Scene MakeCityBlockScene(const CityBlockLoop& loop, uint64_t seed) {
  Scene scene;
  scene.SetBackgroundRgb(Eigen::Vector3d(0.6, 0.72, 0.9));
  AddGround(loop, seed, &scene);
  AddBuildings(loop, seed, &scene);
  AddStreetFurniture(loop, seed, &scene);
  return scene;
}

}  // namespace omnirig::synth
