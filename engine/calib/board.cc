#include "engine/calib/board.h"

#include <cmath>
#include <map>
#include <sstream>

#include <opencv2/aruco.hpp>

#include "engine/util/check.h"

namespace omnirig {
namespace {

// Tags in OpenCV's DICT_APRILTAG_36h11, the family Kalibr's AprilGrid prints.
constexpr int kAprilTag36h11Count = 587;

}  // namespace

BoardSpec BoardSpec::Aprilgrid(int tag_cols, int tag_rows, double tag_size_m, double tag_spacing) {
  BoardSpec spec;
  spec.type = Type::kAprilgrid;
  spec.cols = 2 * tag_cols;
  spec.rows = 2 * tag_rows;
  spec.square_size_m = tag_size_m;
  spec.tag_spacing = tag_spacing;
  spec.aruco_dictionary = cv::aruco::DICT_APRILTAG_36h11;
  return spec;
}

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
  if (type == Type::kAprilgrid) {
    OMNIRIG_CHECK(cols % 2 == 0 && rows % 2 == 0 && (cols / 2) * (rows / 2) <= kAprilTag36h11Count,
                  "board: an AprilGrid has at most " << kAprilTag36h11Count
                                                     << " tags of family 36h11, got "
                                                     << (cols / 2) * (rows / 2));
    OMNIRIG_CHECK(tag_spacing > 0.0 && tag_spacing <= 2.0,
                  "board: tag spacing (gap over tag size) must be in (0, 2], got " << tag_spacing);
  }
}

std::vector<Eigen::Vector3d> BoardSpec::ObjectPoints() const {
  std::vector<Eigen::Vector3d> points;
  points.reserve(NumCorners());
  const auto coordinate = [this](int index) {
    if (type != Type::kAprilgrid) return index * square_size_m;
    return (index / 2) * (1.0 + tag_spacing) * square_size_m + (index % 2) * square_size_m;
  };
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) points.emplace_back(coordinate(c), coordinate(r), 0.0);
  }
  return points;
}

std::string BoardSpec::Describe() const {
  std::ostringstream os;
  if (type == Type::kAprilgrid) {
    os << "aprilgrid " << cols / 2 << "x" << rows / 2 << " tags (" << square_size_m * 1e3
       << " mm, spacing " << tag_spacing << ")";
    return os.str();
  }
  os << (type == Type::kCharuco ? "charuco " : "checkerboard ") << cols << "x" << rows << " ("
     << square_size_m * 1e3 << " mm)";
  return os.str();
}

BoardSpec BoardFromKalibrTarget(const std::string& yaml_text) {
  // Kalibr's target files are flat "key: value  # comment" lines.
  std::map<std::string, std::string> values;
  std::istringstream lines(yaml_text);
  std::string line;
  while (std::getline(lines, line)) {
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    const size_t colon = line.find(':');
    if (colon == std::string::npos) continue;
    const auto trim = [](std::string text) {
      const char* blank = " \t\r'\"";
      const size_t first = text.find_first_not_of(blank);
      if (first == std::string::npos) return std::string();
      return text.substr(first, text.find_last_not_of(blank) - first + 1);
    };
    values[trim(line.substr(0, colon))] = trim(line.substr(colon + 1));
  }
  const auto text = [&values](const std::string& key) {
    const auto it = values.find(key);
    OMNIRIG_CHECK(it != values.end() && !it->second.empty(),
                  "Kalibr target: missing key '" << key << "'");
    return it->second;
  };
  const auto number = [&text](const std::string& key) {
    const std::string value = text(key);
    char* end = nullptr;
    const double parsed = std::strtod(value.c_str(), &end);
    OMNIRIG_CHECK(end == value.c_str() + value.size() && std::isfinite(parsed),
                  "Kalibr target: '" << key << "' must be a number, got '" << value << "'");
    return parsed;
  };
  const auto integer = [&number](const std::string& key) {
    const double value = number(key);
    OMNIRIG_CHECK(value == std::floor(value) && value >= 1 && value <= 1000,
                  "Kalibr target: '" << key << "' must be a positive whole number");
    return static_cast<int>(value);
  };
  const std::string type = text("target_type");
  BoardSpec spec;
  if (type == "aprilgrid") {
    spec = BoardSpec::Aprilgrid(integer("tagCols"), integer("tagRows"), number("tagSize"),
                                number("tagSpacing"));
  } else if (type == "checkerboard") {
    spec.cols = integer("targetCols");
    spec.rows = integer("targetRows");
    spec.square_size_m = number("rowSpacingMeters");
    OMNIRIG_CHECK(std::abs(number("colSpacingMeters") - spec.square_size_m) <= 1e-9,
                  "Kalibr target: a checkerboard with rowSpacingMeters != colSpacingMeters "
                  "(rectangular squares) is not supported");
  } else {
    OMNIRIG_CHECK(false, "Kalibr target: target_type '"
                             << type << "' is not supported (aprilgrid, checkerboard)");
  }
  spec.Check();
  return spec;
}

}  // namespace omnirig
