#include "engine/calib/board.h"

#include <sstream>

#include <opencv2/aruco.hpp>

#include "engine/util/check.h"

namespace omnirig {

void BoardSpec::Check() const {
  OMNIRIG_CHECK(cols >= 2 && rows >= 2 && cols <= 100 && rows <= 100,
                "board: cols and rows (inner corners) must be in [2, 100], got " << cols << " x "
                                                                                 << rows);
  OMNIRIG_CHECK(square_size_m >= 1e-3 && square_size_m <= 10.0,
                "board: square size must be in [1 mm, 10 m], got " << square_size_m * 1e3
                                                                   << " mm");
  if (type == Type::kCharuco) {
    OMNIRIG_CHECK(marker_size_m > 0.0 && marker_size_m < square_size_m,
                  "board: marker size must be positive and smaller than the square, got "
                      << marker_size_m * 1e3 << " mm");
    OMNIRIG_CHECK(aruco_dictionary >= 0 && aruco_dictionary <= cv::aruco::DICT_APRILTAG_36h11,
                  "board: unknown aruco dictionary " << aruco_dictionary);
  }
}

std::vector<Eigen::Vector3d> BoardSpec::ObjectPoints() const {
  std::vector<Eigen::Vector3d> points;
  points.reserve(NumCorners());
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      points.emplace_back(c * square_size_m, r * square_size_m, 0.0);
    }
  }
  return points;
}

std::string BoardSpec::Describe() const {
  std::ostringstream os;
  os << (type == Type::kCharuco ? "charuco " : "checkerboard ") << cols << "x" << rows << " ("
     << square_size_m * 1e3 << " mm)";
  return os.str();
}

}  // namespace omnirig
