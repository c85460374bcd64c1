#pragma once
// Accuracy of a dense map on a synthetic sequence (engine/synth): the kept voxels against the
// scene's true surfaces, and the occupancy grid against the scene's primitives. Test and
// benchmark support: links engine/synth.

#include <vector>

#include "engine/dense/dense_map.h"
#include "engine/geometry/rigid3.h"
#include "engine/synth/presets.h"

namespace omnirig::dense {

struct DenseMapAccuracy {
  int num_points = 0;
  // Each kept voxel's distance to the true surfaces relative to its range from the nearest
  // keyframe; median and the fraction within 1 %.
  double median_relative = 0.0;
  double within_1_percent = 0.0;
  int num_known_cells = 0;  // occupancy cells observed (free or occupied)
  int num_occupied_cells = 0;
  int num_false_occupied_cells = 0;
  double agreement = 0.0;  // fraction of the known cells whose state matches the scene
};

// `true_world_from_map` takes the map's world into the scene's; `keyframes_in_scene` are the
// true positions of the keyframes (for the range). A cell is truly occupied when a surface lies
// within 0.75 cell of its centre at some height of the grid's obstacle band.
DenseMapAccuracy EvaluateDenseMap(const synth::Scene& scene, const Rigid3d& true_world_from_map,
                                  const std::vector<Eigen::Vector3d>& keyframes_in_scene,
                                  const DenseMap& map);

}  // namespace omnirig::dense
