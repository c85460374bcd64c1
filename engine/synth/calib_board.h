#pragma once
// The calibration board (engine/calib) that a rendered checkerboard (engine/synth) shows, for the
// tests and benchmarks that render a board and then detect or fit it. Header-only, so that
// neither library depends on the other.

#include "engine/calib/board.h"
#include "engine/synth/scene.h"

namespace omnirig {

inline BoardSpec ToBoardSpec(const synth::CheckerboardSpec& spec) {
  BoardSpec board;
  board.cols = spec.cols;
  board.rows = spec.rows;
  board.square_size_m = spec.square_size_m;
  return board;
}

}  // namespace omnirig
