#pragma once
// Pose-graph optimisation for loop closure (as Ceres' examples/slam/pose_graph_3d): the
// keyframes' rig_from_world as nodes, relative poses as edges (consecutive keyframes as the map
// holds them, plus the loops' measured ones), each edge's error weighted by its standard
// deviations. Closing a loop spreads the drift the loop edge reveals along the keyframes between
// its ends, before the global bundle adjustment refines everything against the images.

#include <map>
#include <set>
#include <string>
#include <vector>

#include "engine/geometry/rigid3.h"
#include "engine/util/solver_summary.h"

namespace omnirig::slam {

struct PoseGraphEdge {
  int from = -1;  // keyframe (frame index)
  int to = -1;
  Rigid3d to_from_from;  // rig_from_world[to] * rig_from_world[from]^-1, measured
  double sigma_m = 0.01;
  double sigma_rad = 0.002;
};

struct PoseGraphReport {
  int num_poses = 0;
  SolverSummary solver;
};

// Adjusts `rig_from_world` (keyframe -> pose) to the edges, holding the poses in `fixed`
// constant (the gauge: at least one is needed; throws InvalidArgument otherwise, or for an edge
// between unknown poses).
PoseGraphReport OptimisePoseGraph(const std::vector<PoseGraphEdge>& edges,
                                  const std::set<int>& fixed, int num_threads,
                                  std::map<int, Rigid3d>* rig_from_world);

}  // namespace omnirig::slam
