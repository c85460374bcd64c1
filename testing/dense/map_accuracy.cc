#include "testing/dense/map_accuracy.h"

#include <algorithm>
#include <cmath>

#include "testing/slam/surface_distance.h"

namespace omnirig::dense {
namespace {

void ScoreOccupancy(const synth::Scene& scene, const Rigid3d& true_world_from_map,
                    const DenseMapOptions& options, const OccupancyGrid& grid,
                    DenseMapAccuracy* accuracy) {
  int agree = 0;
  for (int r = 0; r < grid.cells.rows; ++r) {
    for (int c = 0; c < grid.cells.cols; ++c) {
      const uint8_t state = grid.cells.at<uint8_t>(r, c);
      if (state == OccupancyGrid::kUnknown) continue;
      ++accuracy->num_known_cells;
      accuracy->num_occupied_cells += state == OccupancyGrid::kOccupied;
      const double x = grid.origin_m.x() + (c + 0.5) * grid.cell_m;
      const double y = grid.origin_m.y() + (grid.cells.rows - 1 - r + 0.5) * grid.cell_m;
      bool truly_occupied = false;
      for (double h = options.obstacle_min_height_m; h <= options.obstacle_max_height_m;
           h += 0.5 * grid.cell_m) {
        const Eigen::Vector3d in_map(x, y, -(grid.floor_height_m + h));
        if (slam::DistanceToSceneSurface(scene, true_world_from_map * in_map) <=
            0.75 * grid.cell_m) {
          truly_occupied = true;
          break;
        }
      }
      agree += truly_occupied == (state == OccupancyGrid::kOccupied);
      accuracy->num_false_occupied_cells += !truly_occupied && state == OccupancyGrid::kOccupied;
    }
  }
  accuracy->agreement = static_cast<double>(agree) / std::max(accuracy->num_known_cells, 1);
}

}  // namespace

DenseMapAccuracy EvaluateDenseMap(const synth::Scene& scene, const Rigid3d& true_world_from_map,
                                  const std::vector<Eigen::Vector3d>& keyframes_in_scene,
                                  const DenseMap& map) {
  DenseMapAccuracy accuracy;
  const PlyCloud cloud = map.Cloud();
  std::vector<double> relative;
  relative.reserve(cloud.size());
  for (const Eigen::Vector3f& p : cloud.positions) {
    const Eigen::Vector3d in_scene = true_world_from_map * p.cast<double>();
    double range = INFINITY;
    for (const Eigen::Vector3d& keyframe : keyframes_in_scene) {
      range = std::min(range, (in_scene - keyframe).norm());
    }
    relative.push_back(slam::DistanceToSceneSurface(scene, in_scene) / range);
  }
  accuracy.num_points = static_cast<int>(relative.size());
  if (!relative.empty()) {
    std::sort(relative.begin(), relative.end());
    accuracy.median_relative = relative[relative.size() / 2];
    accuracy.within_1_percent =
        static_cast<double>(std::upper_bound(relative.begin(), relative.end(), 0.01) -
                            relative.begin()) /
        relative.size();
  }
  ScoreOccupancy(scene, true_world_from_map, map.options(), map.Occupancy(), &accuracy);
  return accuracy;
}

}  // namespace omnirig::dense
