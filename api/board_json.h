#pragma once
// The "board" object of the jobs that detect a calibration board (calibration, relative_pose):
//   {"type": "checkerboard" | "charuco" (default checkerboard), "cols", "rows" (inner corners),
//    "square_size_mm", "marker_size_mm" (charuco; optional otherwise), "aruco_dictionary"}

#include <nlohmann/json.hpp>

#include "engine/calib/board.h"

namespace omnirig::api {

// Throws InvalidArgument naming the field ("board.cols", ...) for unknown fields, wrong types
// and a board that fails BoardSpec::Check.
BoardSpec BoardFromJson(const nlohmann::json& board);

}  // namespace omnirig::api
