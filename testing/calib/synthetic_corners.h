#pragma once
// Exact board corners from a known camera and random board poses, for tests and benchmarks of
// calibration without a renderer.

#include <cstdint>
#include <vector>

#include "engine/calib/board.h"
#include "engine/calib/calibrate.h"
#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"

namespace omnirig {

struct SyntheticCornerOptions {
  int num_views = 20;
  double noise_px = 0.0;          // std of Gaussian noise per axis
  double outlier_fraction = 0.0;  // corners displaced by 5 to 20 px
  double min_distance_m = 0.4;    // board centre distance from the camera
  double max_distance_m = 0.9;
  // Board-centre elevation above the plane z = 0 of the camera frame (the mirror axis is z).
  double min_elevation_rad = -0.2;
  double max_elevation_rad = 0.9;
  double max_tilt_rad = 0.6;  // board normal's deviation from facing the camera
  uint64_t seed = 1;
};

struct SyntheticCornerSet {
  std::vector<CalibrationView> views;
  std::vector<Rigid3d> cam_from_board;
  std::vector<std::vector<bool>> is_outlier;  // per view, per corner
};

// The board of the synthetic-corner tests: 8 x 6 inner corners, 40 mm squares.
inline BoardSpec SyntheticBoard() {
  BoardSpec board;
  board.cols = 8;
  board.rows = 6;
  board.square_size_m = 0.04;
  return board;
}

// Views whose every corner projects inside the image (poses are redrawn until they do).
SyntheticCornerSet MakeSyntheticCornerSet(const CameraModel& camera, const BoardSpec& board,
                                          const SyntheticCornerOptions& options);

}  // namespace omnirig
