#include "testing/calib/synthetic_corners.h"

#include <cmath>
#include <random>

namespace omnirig {
namespace {

// A pose that puts the board's centre in direction (azimuth, elevation) at `distance`, facing
// the camera up to a random tilt.
Rigid3d RandomBoardPose(const BoardSpec& board, const SyntheticCornerOptions& options,
                        std::mt19937_64* rng) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double azimuth = 2.0 * M_PI * unit(*rng);
  const double elevation = options.min_elevation_rad +
                           (options.max_elevation_rad - options.min_elevation_rad) * unit(*rng);
  const double distance =
      options.min_distance_m + (options.max_distance_m - options.min_distance_m) * unit(*rng);
  const Eigen::Vector3d direction(std::cos(elevation) * std::cos(azimuth),
                                  std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
  // Board z axis points away from the camera; its x axis roughly horizontal.
  const Eigen::Vector3d z = direction;
  Eigen::Vector3d x = Eigen::Vector3d::UnitZ().cross(z);
  if (x.norm() < 1e-6) x = Eigen::Vector3d::UnitX();
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d facing;
  facing << x, y, z;
  const Eigen::Vector3d axis = Eigen::Vector3d(unit(*rng) - 0.5, unit(*rng) - 0.5,
                                               unit(*rng) - 0.5).normalized();
  const Eigen::AngleAxisd tilt(options.max_tilt_rad * (2.0 * unit(*rng) - 1.0), axis);
  const Eigen::AngleAxisd spin(2.0 * M_PI * unit(*rng), Eigen::Vector3d::UnitZ());
  const Eigen::Matrix3d rotation = facing * tilt.toRotationMatrix() * spin.toRotationMatrix();
  const Eigen::Vector3d centre_in_board((board.cols - 1) * board.square_size_m / 2.0,
                                        (board.rows - 1) * board.square_size_m / 2.0, 0.0);
  return Rigid3d(Eigen::Quaterniond(rotation), distance * direction - rotation * centre_in_board);
}

}  // namespace

SyntheticCornerSet MakeSyntheticCornerSet(const CameraModel& camera, const BoardSpec& board,
                                          const SyntheticCornerOptions& options) {
  std::mt19937_64 rng(options.seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  SyntheticCornerSet set;
  for (int attempt = 0; static_cast<int>(set.views.size()) < options.num_views; ++attempt) {
    OMNIRIG_CHECK(attempt < 100000, "synthetic corners: no board pose fits in the image");
    const Rigid3d cam_from_board = RandomBoardPose(board, options, &rng);
    CalibrationView view;
    view.name = "view" + std::to_string(set.views.size());
    std::vector<bool> outliers;
    bool inside = true;
    for (size_t i = 0; i < object_points.size() && inside; ++i) {
      const auto pixel = Project(camera.intrinsics, cam_from_board * object_points[i]);
      inside = pixel && pixel->x() >= 2 && pixel->y() >= 2 && pixel->x() <= camera.width - 3 &&
               pixel->y() <= camera.height - 3;
      if (!inside) break;
      Eigen::Vector2d measured = *pixel + options.noise_px * Eigen::Vector2d(noise(rng), noise(rng));
      const bool outlier = unit(rng) < options.outlier_fraction;
      if (outlier) {
        const double angle = 2.0 * M_PI * unit(rng);
        measured += (5.0 + 15.0 * unit(rng)) * Eigen::Vector2d(std::cos(angle), std::sin(angle));
      }
      outliers.push_back(outlier);
      view.detection.corners_px.push_back(measured);
      view.detection.corner_ids.push_back(static_cast<int>(i));
    }
    if (!inside) continue;
    view.detection.found = true;
    set.views.push_back(std::move(view));
    set.cam_from_board.push_back(cam_from_board);
    set.is_outlier.push_back(std::move(outliers));
  }
  return set;
}

}  // namespace omnirig
