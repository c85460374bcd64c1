#pragma once
// The calibration board (engine/calib) that a rendered checkerboard (engine/synth) shows, for the
// tests and benchmarks that render a board and then detect or fit it. Header-only, so that
// neither library depends on the other.

#include <algorithm>
#include <vector>

#include <Eigen/Core>

#include "engine/calib/board.h"
#include "engine/calib/detect.h"
#include "engine/synth/scene.h"

namespace omnirig {

inline BoardSpec ToBoardSpec(const synth::CheckerboardSpec& spec) {
  BoardSpec board;
  board.cols = spec.cols;
  board.rows = spec.rows;
  board.square_size_m = spec.square_size_m;
  return board;
}

// Mean distance in pixels of a detection's corners to the rendered truth (indexed by corner id).
// A checkerboard's numbering is defined up to the 180 degree turn of the board (both are rigid
// poses), so the better of the two is taken.
inline double MeanCornerError(const BoardDetection& detection,
                              const std::vector<Eigen::Vector2d>& truth) {
  double direct = 0.0, turned = 0.0;
  const int n = static_cast<int>(truth.size());
  for (size_t i = 0; i < detection.corners_px.size(); ++i) {
    const int id = detection.corner_ids[i];
    direct += (detection.corners_px[i] - truth[id]).norm();
    turned += (detection.corners_px[i] - truth[n - 1 - id]).norm();
  }
  return std::min(direct, turned) / std::max<size_t>(1, detection.corners_px.size());
}

}  // namespace omnirig
