#include "engine/rig/relpose_corner_order.h"

#include <cmath>
#include <limits>

#include <Eigen/Geometry>

namespace omnirig {
namespace {

// The rigid motion of the board plane that carries corner id onto corner permutation[id]:
// exact for a grid symmetry, so the least-squares fit (Umeyama, no scale) recovers it.
Rigid3d FitBoardMotion(const std::vector<Eigen::Vector3d>& object_points,
                       const std::vector<int>& permutation) {
  Eigen::Matrix3Xd from(3, object_points.size()), to(3, object_points.size());
  for (size_t id = 0; id < object_points.size(); ++id) {
    from.col(id) = object_points[id];
    to.col(id) = object_points[permutation[id]];
  }
  const Eigen::Matrix4d m = Eigen::umeyama(from, to, false);
  return Rigid3d(Eigen::Quaterniond(Eigen::Matrix3d(m.topLeftCorner<3, 3>())),
                 m.topRightCorner<3, 1>());
}

struct Disagreement {
  double rotation_deg;
  double translation_fraction;
};

Disagreement Compare(const Rigid3d& a, const Rigid3d& b, double scale_m) {
  return {RotationDistanceRad(a.rotation, b.rotation) * 180.0 / M_PI,
          (a.translation - b.translation).norm() / std::max(scale_m, 1e-9)};
}

}  // namespace

std::vector<BoardSymmetry> BoardGridSymmetries(const BoardSpec& board) {
  const int cols = board.cols, rows = board.rows, n = board.NumCorners();
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  std::vector<std::vector<int>> permutations;
  std::vector<int> identity(n), half_turn(n);
  for (int id = 0; id < n; ++id) {
    identity[id] = id;
    half_turn[id] = n - 1 - id;  // (r, c) -> (rows-1-r, cols-1-c) in row-major ids
  }
  permutations.push_back(identity);
  permutations.push_back(half_turn);
  if (cols == rows) {
    std::vector<int> quarter(n), three_quarter(n);
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        quarter[r * cols + c] = c * cols + (cols - 1 - r);
        three_quarter[c * cols + (cols - 1 - r)] = r * cols + c;
      }
    }
    permutations.push_back(quarter);
    permutations.push_back(three_quarter);
  }
  std::vector<BoardSymmetry> symmetries;
  for (auto& permutation : permutations) {
    const Rigid3d motion = FitBoardMotion(object_points, permutation);
    symmetries.push_back({std::move(permutation), motion});
  }
  return symmetries;
}

std::vector<int> ChooseConsistentCandidates(const std::vector<std::vector<Rigid3d>>& candidates,
                                            const std::vector<double>& scale_m,
                                            double max_rotation_deg,
                                            double max_translation_fraction) {
  const size_t num_pairs = candidates.size();
  // For a reference candidate, each pair's best match and whether it agrees.
  const auto match = [&](const Rigid3d& reference, size_t j, double* cost) {
    int best = -1;
    double best_cost = std::numeric_limits<double>::infinity();
    for (size_t k = 0; k < candidates[j].size(); ++k) {
      const Disagreement d = Compare(reference, candidates[j][k], scale_m[j]);
      if (d.rotation_deg > max_rotation_deg || d.translation_fraction > max_translation_fraction) {
        continue;
      }
      const double c = d.rotation_deg / max_rotation_deg +
                       d.translation_fraction / max_translation_fraction;
      if (c < best_cost) best_cost = c, best = static_cast<int>(k);
    }
    if (best >= 0) *cost += best_cost;
    return best;
  };
  std::vector<int> chosen(num_pairs, -1);
  int best_support = 0;
  double best_cost = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < num_pairs; ++i) {
    for (const Rigid3d& reference : candidates[i]) {
      std::vector<int> assignment(num_pairs, -1);
      int support = 0;
      double cost = 0.0;
      for (size_t j = 0; j < num_pairs; ++j) {
        assignment[j] = match(reference, j, &cost);
        if (assignment[j] >= 0) ++support;
      }
      if (support > best_support || (support == best_support && cost < best_cost)) {
        best_support = support, best_cost = cost, chosen = assignment;
      }
    }
  }
  return chosen;
}

}  // namespace omnirig
