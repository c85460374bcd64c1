#include "engine/calib/grid_check.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include <Eigen/Dense>

#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

// The quadratic fitted to the `num_neighbours` usable points of one grid line nearest to index
// k (excluding k), evaluated at k; nullopt with fewer than three such points.
std::optional<Eigen::Vector2d> PredictAlongLine(const std::vector<Eigen::Vector2d>& grid,
                                                const std::vector<bool>& usable, int first,
                                                int stride, int length, int k, int num_neighbours) {
  Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
  Eigen::Matrix<double, 3, 2> rhs = Eigen::Matrix<double, 3, 2>::Zero();
  int count = 0;
  // Offsets in the order -1, +1, -2, +2, ...: interpolation where the line allows it.
  for (int distance = 1; distance < length && count < num_neighbours; ++distance) {
    for (int sign : {-1, 1}) {
      const int j = k + sign * distance;
      if (j < 0 || j >= length || count >= num_neighbours || !usable[first + j * stride]) continue;
      const double t = sign * distance;
      const Eigen::Vector3d basis(1.0, t, t * t);
      normal += basis * basis.transpose();
      rhs += basis * grid[first + j * stride].transpose();
      ++count;
    }
  }
  // Three distinct offsets make the 3x3 system regular.
  if (count < 3) return std::nullopt;
  const Eigen::Matrix<double, 3, 2> coefficients = normal.ldlt().solve(rhs);
  return Eigen::Vector2d(coefficients.row(0).transpose());
}

// Distance from `point` to the nearest usable 4-neighbour of corner (row, col).
double NearestNeighbourPx(const std::vector<Eigen::Vector2d>& grid, const std::vector<bool>& usable,
                          int cols, int rows, int row, int col, const Eigen::Vector2d& point) {
  double best = std::numeric_limits<double>::infinity();
  const int offsets[4][2] = {{0, 1}, {0, -1}, {1, 0}, {-1, 0}};
  for (const auto& offset : offsets) {
    const int r = row + offset[0], c = col + offset[1];
    if (r < 0 || c < 0 || r >= rows || c >= cols || !usable[r * cols + c]) continue;
    best = std::min(best, (grid[r * cols + c] - point).norm());
  }
  return best;
}

}  // namespace

void GridCheckOptions::Check() const {
  OMNIRIG_CHECK_POSITIVE(min_deviation_px);
  OMNIRIG_CHECK_POSITIVE(max_relative_deviation);
  OMNIRIG_CHECK_AT_LEAST(num_neighbours, 3);
  OMNIRIG_CHECK_NON_NEGATIVE(max_flagged);
}

std::vector<GridCornerPrediction> PredictFromGridNeighbours(
    const std::vector<Eigen::Vector2d>& grid, int cols, int rows,
    const std::vector<bool>& usable_in, int num_neighbours) {
  OMNIRIG_CHECK(cols >= 1 && rows >= 1 && static_cast<int>(grid.size()) == cols * rows,
                "grid check: grid of " << grid.size() << " corners for " << cols << " x " << rows);
  OMNIRIG_CHECK(usable_in.empty() || usable_in.size() == grid.size(),
                "grid check: usable mask of the wrong size");
  const std::vector<bool> usable =
      usable_in.empty() ? std::vector<bool>(grid.size(), true) : usable_in;
  std::vector<GridCornerPrediction> predictions(grid.size());
  for (int row = 0; row < rows; ++row) {
    for (int col = 0; col < cols; ++col) {
      const int id = row * cols + col;
      const auto along_row =
          PredictAlongLine(grid, usable, row * cols, 1, cols, col, num_neighbours);
      const auto along_col = PredictAlongLine(grid, usable, col, cols, rows, row, num_neighbours);
      GridCornerPrediction& prediction = predictions[id];
      if (!along_row && !along_col) continue;
      prediction.valid = true;
      double deviation = std::numeric_limits<double>::infinity();
      Eigen::Vector2d sum = Eigen::Vector2d::Zero();
      int n = 0;
      for (const auto& line : {along_row, along_col}) {
        if (!line) continue;
        deviation = std::min(deviation, (grid[id] - *line).norm());
        sum += *line;
        ++n;
      }
      prediction.predicted_px = sum / n;
      prediction.deviation_px = deviation;
      prediction.square_px =
          NearestNeighbourPx(grid, usable, cols, rows, row, col, prediction.predicted_px);
    }
  }
  return predictions;
}

double GridDeviationLimitPx(const GridCheckOptions& options, double square_px) {
  return std::max(options.min_deviation_px, options.max_relative_deviation * square_px);
}

std::vector<int> FindInconsistentCorners(const std::vector<Eigen::Vector2d>& grid, int cols,
                                         int rows, const GridCheckOptions& options) {
  options.Check();
  std::vector<bool> usable(grid.size(), true);
  std::vector<int> flagged;
  while (static_cast<int>(flagged.size()) < options.max_flagged) {
    const std::vector<GridCornerPrediction> predictions =
        PredictFromGridNeighbours(grid, cols, rows, usable, options.num_neighbours);
    int worst = -1;
    double worst_ratio = 1.0;
    for (size_t id = 0; id < grid.size(); ++id) {
      const GridCornerPrediction& prediction = predictions[id];
      if (!usable[id] || !prediction.valid) continue;
      const double ratio =
          prediction.deviation_px / GridDeviationLimitPx(options, prediction.square_px);
      if (ratio > worst_ratio) {
        worst_ratio = ratio;
        worst = static_cast<int>(id);
      }
    }
    if (worst < 0) break;
    usable[worst] = false;
    flagged.push_back(worst);
  }
  return flagged;
}

}  // namespace omnirig
