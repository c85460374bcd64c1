#pragma once
// Calibration boards: a planar checkerboard, ChArUco board or Kalibr AprilGrid and its corners
// in the board frame.
//
// Board frame: origin at the first inner corner, x along a row (increasing column), y along a
// column (increasing row), z = 0 on the board, metres. Corners are numbered row-major:
// id = row * cols + col. For a ChArUco board the ids are OpenCV's ChArUco corner ids, which use
// the same row-major numbering of the inner corners.
//
// An AprilGrid (Kalibr's target: tag_cols x tag_rows AprilTags of family 36h11, ids 0, 1, ...
// row by row from the board's origin, tag_spacing x tag_size apart) has the four corners of every
// tag as its points, numbered as Kalibr numbers them: cols = 2 tag_cols, rows = 2 tag_rows, the
// point (r, c) at x = (c / 2) (1 + tag_spacing) tag_size + (c % 2) tag_size and y likewise, so
// that tag t = tag_row * tag_cols + tag_col has its corners at rows 2 tag_row, 2 tag_row + 1 and
// columns 2 tag_col, 2 tag_col + 1. The origin is the first corner of tag 0, y pointing from tag
// 0 towards the tag above it as printed.

#include <string>
#include <vector>

#include <Eigen/Core>

namespace omnirig {

struct BoardSpec {
  enum class Type { kCheckerboard, kCharuco, kAprilgrid };
  Type type = Type::kCheckerboard;
  // Inner corners per row (cols) and per column (rows); a ChArUco board has (cols + 1) x
  // (rows + 1) squares, an AprilGrid cols / 2 x rows / 2 tags.
  int cols = 0;
  int rows = 0;
  double square_size_m = 0.0;  // an AprilGrid's tag size, edge to edge
  double marker_size_m = 0.0;  // ChArUco only: side of the ArUco markers
  int aruco_dictionary = 0;    // ChArUco only: cv::aruco::PREDEFINED_DICTIONARY_NAME
  double tag_spacing = 0.0;    // AprilGrid only: the gap between tags over the tag size

  // Kalibr's AprilGrid of tag_cols x tag_rows tags (family 36h11).
  static BoardSpec Aprilgrid(int tag_cols, int tag_rows, double tag_size_m, double tag_spacing);

  // Throws InvalidArgument for sizes under 2x2 or over 100x100, square sizes outside
  // [1 mm, 10 m], a marker not smaller than the square, an unknown dictionary, an AprilGrid of
  // more tags than the family has or with a spacing outside (0, 2].
  void Check() const;
  int NumCorners() const { return cols * rows; }
  // Corner positions in the board frame, z = 0, row-major, metres.
  std::vector<Eigen::Vector3d> ObjectPoints() const;
  // "checkerboard 7x11 (30 mm)", "aprilgrid 6x6 tags (88 mm, spacing 0.3)" for messages.
  std::string Describe() const;
};

// A Kalibr target YAML (target_type 'aprilgrid' with tagCols, tagRows, tagSize, tagSpacing, or
// 'checkerboard' with targetCols, targetRows, rowSpacingMeters, colSpacingMeters equal) as a
// board. Throws InvalidArgument naming the key that is missing or wrong, or the target type
// omnirig does not read (circlegrid).
BoardSpec BoardFromKalibrTarget(const std::string& yaml_text);

}  // namespace omnirig
