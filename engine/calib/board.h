#pragma once
// Calibration boards: a planar checkerboard or ChArUco board and its corners in the board frame.
//
// Board frame: origin at the first inner corner, x along a row (increasing column), y along a
// column (increasing row), z = 0 on the board, metres. Corners are numbered row-major:
// id = row * cols + col. For a ChArUco board the ids are OpenCV's ChArUco corner ids, which use
// the same row-major numbering of the inner corners.

#include <string>
#include <vector>

#include <Eigen/Core>

namespace omnirig {

struct BoardSpec {
  enum class Type { kCheckerboard, kCharuco };
  Type type = Type::kCheckerboard;
  // Inner corners per row (cols) and per column (rows), for both types; a ChArUco board has
  // (cols + 1) x (rows + 1) squares.
  int cols = 0;
  int rows = 0;
  double square_size_m = 0.0;
  double marker_size_m = 0.0;  // ChArUco only: side of the ArUco markers
  int aruco_dictionary = 0;    // ChArUco only: cv::aruco::PREDEFINED_DICTIONARY_NAME

  // Throws InvalidArgument for sizes under 2x2 or over 100x100, square sizes outside
  // [1 mm, 10 m], a marker not smaller than the square, an unknown dictionary.
  void Check() const;
  int NumCorners() const { return cols * rows; }
  // Corner positions in the board frame, z = 0, row-major, metres.
  std::vector<Eigen::Vector3d> ObjectPoints() const;
  // "checkerboard 7x11 (30 mm)" for messages.
  std::string Describe() const;
};

}  // namespace omnirig
