#pragma once
// Consistent corner orders between the two cameras of a stereo pair.
//
// A checkerboard detector numbers corners by their place in the grid it sees. The grid of
// inner corners is unchanged by a half turn (and by quarter turns when cols == rows), so a
// detector may number a board from either end; when the colouring is symmetric too (odd x odd
// squares) no detector can tell the two apart. Each such symmetry is a permutation of corner
// ids and a rigid motion of the board frame; trying each for cam1 turns every pair into a few
// candidate rig poses, of which the true one is the one all pairs share.

#include <vector>

#include "engine/calib/board.h"
#include "engine/geometry/rigid3.h"

namespace omnirig {

// A symmetry of the board's corner grid: detected id `id` may really be corner
// permutation[id], whose position is board_from_board * ObjectPoints()[id].
struct BoardSymmetry {
  std::vector<int> permutation;
  Rigid3d board_from_board;
};

// The identity first, then the half turn, then (square grids only) the two quarter turns.
std::vector<BoardSymmetry> BoardGridSymmetries(const BoardSpec& board);

// candidates[i][k]: pair i's cam0_from_cam1 under its k-th corner order (empty when the pair
// has no estimate); scale_m[i]: a length for pair i's translation tolerance (the board's
// distance). Picks the candidate with which the most pairs agree (rotation within
// `max_rotation_deg`, translation within `max_translation_fraction` * scale_m of the pair
// compared), ties broken by the smallest summed disagreement, and returns for every pair the
// index of its candidate closest to that consensus, or -1 when none agrees with it.
std::vector<int> ChooseConsistentCandidates(const std::vector<std::vector<Rigid3d>>& candidates,
                                            const std::vector<double>& scale_m,
                                            double max_rotation_deg,
                                            double max_translation_fraction);

}  // namespace omnirig
