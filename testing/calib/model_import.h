#pragma once
// Readers for tests and benchmarks: OpenCV omnidir FileStorage, which engine/calib/model_io.h
// exports (for round trips; its Kalibr camchain reader is the product's), and board corners
// stored the way OpenCV's calibration samples store them (the real-data test and bench_calib).

#include <string>
#include <vector>

#include "engine/calib/board.h"
#include "engine/calib/calibrate.h"
#include "engine/calib/model_io.h"
#include "engine/geometry/camera_model.h"

namespace omnirig {

// Parses an OpenCV omnidir FileStorage document (YAML or XML text). Throws InvalidArgument
// naming the missing or malformed node.
CameraModel FromOpenCvOmnidir(const std::string& text);

// The corners of a FileStorage file (YAML or XML) holding the sequences "objectPoints" (per
// view, board points in the board's plane z = 0, as 3-channel matrices) and "imagePoints" (per
// view, pixels as 2-channel matrices), as OpenCV's omnidir tutorial data and
// cv::omnidir::calibrate's inputs are stored. Object points times `object_points_to_m` must lie
// on `board`'s corner grid (x along the columns, y along the rows, spacing square_size_m); they
// become corner ids. Views are named "view0", "view1", ... and marked found. Throws
// InvalidArgument for an unreadable file, missing or mismatched sequences, or a point off the
// grid.
std::vector<CalibrationView> ReadOpenCvCornerViews(const std::string& path, const BoardSpec& board,
                                                   double object_points_to_m = 1.0);

}  // namespace omnirig
