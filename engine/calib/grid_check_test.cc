#include "engine/calib/grid_check.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "engine/synth/presets.h"
#include "engine/util/check.h"

namespace omnirig {
namespace {

// Exact corner projections of board views as the synthetic sets draw them (the default
// catadioptric camera, 1024x768, boards 0.35-1.2 m away, tilted up to 50 degrees): grids curved
// by the mirror, without rendering anything.
std::vector<std::vector<Eigen::Vector2d>> CurvedGrids(const synth::CheckerboardSpec& board,
                                                      int num_views, uint64_t seed) {
  const synth::SynthCamera camera = synth::DefaultCamera();
  std::vector<std::vector<Eigen::Vector2d>> grids;
  for (int v = 0; v < num_views; ++v) {
    const Rigid3d cam_from_board = synth::SampleBoardPose(
        {camera}, {Rigid3d()}, board, synth::BoardPoseOptions(), v, num_views, seed);
    grids.push_back(synth::ProjectBoardCorners(camera, cam_from_board, board));
  }
  return grids;
}

void AddNoise(double sigma_px, std::mt19937* rng, std::vector<Eigen::Vector2d>* grid) {
  std::normal_distribution<double> noise(0.0, sigma_px);
  for (Eigen::Vector2d& corner : *grid) corner += Eigen::Vector2d(noise(*rng), noise(*rng));
}

TEST(GridCheck, PredictsCurvedGridsClosely) {
  const synth::CheckerboardSpec board;  // 8 x 6
  for (const auto& grid : CurvedGrids(board, 20, 7)) {
    const auto predictions = PredictFromGridNeighbours(grid, board.cols, board.rows);
    for (size_t id = 0; id < grid.size(); ++id) {
      // Every corner has a row and a column with at least three other corners.
      ASSERT_TRUE(predictions[id].valid) << id;
      EXPECT_GT(predictions[id].square_px, 5.0);
      // The model's own error on exact corners, far below the check's limit (bench numbers in
      // grid_check.h: at most 0.035 squares on the renders).
      EXPECT_LT(predictions[id].deviation_px, 0.06 * predictions[id].square_px) << id;
    }
  }
}

TEST(GridCheck, KeepsCleanGridsIntact) {
  std::mt19937 rng(11);
  for (const synth::CheckerboardSpec& board :
       {synth::CheckerboardSpec(), synth::CheckerboardSpec{11, 8, 0.04, 0.03}}) {
    for (auto grid : CurvedGrids(board, 30, 3)) {
      // Corner noise well above the detector's (0.02-0.15 px on the renders).
      AddNoise(0.3, &rng, &grid);
      EXPECT_TRUE(
          FindInconsistentCorners(grid, board.cols, board.rows, GridCheckOptions()).empty());
    }
  }
}

TEST(GridCheck, FlagsExactlyTheDisplacedCorner) {
  const synth::CheckerboardSpec board;
  std::mt19937 rng(5);
  const int n = board.cols * board.rows;
  // A board corner (the reproduction case: id 47), an edge corner, an inner corner, and more.
  std::vector<int> ids = {47, 0, 3, 20, 41};
  std::uniform_int_distribution<int> any(0, n - 1);
  for (int i = 0; i < 15; ++i) ids.push_back(any(rng));
  const auto grids = CurvedGrids(board, static_cast<int>(ids.size()), 9);
  for (size_t k = 0; k < ids.size(); ++k) {
    std::vector<Eigen::Vector2d> grid = grids[k];
    AddNoise(0.1, &rng, &grid);
    const int id = ids[k];
    // Half a square towards a neighbour: where OpenCV's quad linking put corner 47 of the
    // reproduction case.
    const int neighbour = id % board.cols > 0 ? id - 1 : id + 1;
    grid[id] += 0.5 * (grid[neighbour] - grid[id]);
    const std::vector<int> flagged =
        FindInconsistentCorners(grid, board.cols, board.rows, GridCheckOptions());
    ASSERT_EQ(flagged.size(), 1u) << "view " << k << " corner " << id;
    EXPECT_EQ(flagged[0], id);
    // Left out of its neighbours' predictions, it is predicted where it belongs.
    std::vector<bool> usable(grid.size(), true);
    usable[id] = false;
    const auto predictions = PredictFromGridNeighbours(grid, board.cols, board.rows, usable);
    EXPECT_LT((predictions[id].predicted_px - grids[k][id]).norm(),
              0.1 * predictions[id].square_px);
  }
}

TEST(GridCheck, FlagsTwoDisplacedCornersButNotTheirNeighbours) {
  const synth::CheckerboardSpec board;
  std::vector<Eigen::Vector2d> grid = CurvedGrids(board, 1, 4)[0];
  // Two wrong corners in one row, two apart: each disturbs the row predictions of the
  // corners between and beside them, which their columns still predict well.
  grid[9] += 0.9 * (grid[10] - grid[9]);    // almost onto corner 10
  grid[11] += 0.5 * (grid[19] - grid[11]);  // half way down to the next row
  std::vector<int> flagged =
      FindInconsistentCorners(grid, board.cols, board.rows, GridCheckOptions());
  std::sort(flagged.begin(), flagged.end());
  EXPECT_EQ(flagged, std::vector<int>({9, 11}));
}

TEST(GridCheck, SmallGridsAndBadInput) {
  // A 3 x 3 grid: no line has three other corners, so nothing is predicted or flagged.
  std::vector<Eigen::Vector2d> grid;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) grid.emplace_back(10.0 * c, 10.0 * r);
  }
  grid[4] += Eigen::Vector2d(4.0, 4.0);
  EXPECT_FALSE(PredictFromGridNeighbours(grid, 3, 3)[4].valid);
  EXPECT_TRUE(FindInconsistentCorners(grid, 3, 3, GridCheckOptions()).empty());
  EXPECT_THROW(PredictFromGridNeighbours(grid, 4, 3), InvalidArgument);
  GridCheckOptions options;
  options.num_neighbours = 2;
  EXPECT_THROW(FindInconsistentCorners(grid, 3, 3, options), InvalidArgument);
}

}  // namespace
}  // namespace omnirig
